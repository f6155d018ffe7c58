#!/usr/bin/env bash
# The Snakemake export end to end (run by .ci/run). A small experiment of the
# quickstart's structure (tests/data/sharded.toml) exported with 4 training
# shards per variant runs under `snakemake --cores 2`; on the
# way, a shard with nowhere to write fails the workflow with the shard named, and
# the re-run resumes without redoing the finished shards. The result must
# equal `alnlab run`'s on the same manifest; so must a small experiment's
# with rounds of the planner's own data.
#
# Usage: tests/snakemake.sh ALNLAB SNAKEMAKE PYTHON WORK_DIR [DIRECT_RUNS DIRECT_REPORTS]
#
# The direct runs go to DIRECT_RUNS and DIRECT_REPORTS when given (the
# suite passes its runs and reports folders), else under WORK_DIR.
set -euo pipefail
alnlab=$(realpath "$1")
snakemake=$2
python=$3
rm -rf "$4"
mkdir -p "$4"
# Absolute: the workflow runs in its own folder, and targets must name the
# rules' (absolute) outputs.
work=$(realpath "$4")
direct=${5:-$work/direct}
direct_reports=${6:-$work/direct-reports}

sharded=tests/data/sharded.toml
"$alnlab" -q run "$sharded" --out "$direct" --reports "$direct_reports" >/dev/null
"$alnlab" export snakemake "$sharded" --shards 4 -o "$work/wf" \
  --out "$work/runs" --reports "$work/reports" --alnlab "$alnlab" >/dev/null
smk() { "$snakemake" --snakefile "$work/wf/Snakefile" --directory "$work/wf" --cores 2 "$@"; }
mark="$work/runs/sharded/snakemake"

# Variant walk up to two of its four shards.
smk "$mark/walk/train-shard-1-of-4.done" "$mark/walk/train-shard-2-of-4.done" >"$work/first.log" 2>&1
stamps() { stat -c '%n %y' "$mark/walk/train-shard-1-of-4.done" "$mark/walk/train-shard-2-of-4.done"; }
before=$(stamps)

# A bad place for the remaining shards: a file stands where shard 3's and
# 4's folders go. (A damaged input would not do: the cache re-hashes what it
# reuses and makes a damaged artifact again.)
keydir=$(ls -d "$work"/runs/shards/train/*/)
[ "$(echo "$keydir" | wc -l)" = 1 ]
touch "${keydir}3-of-4" "${keydir}4-of-4"
if smk >"$work/failed.log" 2>&1; then
  echo "snakemake: the workflow should have failed on walk's shards 3 and 4"
  exit 1
fi
grep -A8 "Error in rule train_shard" "$work/failed.log" | grep -Eq "walk/train-shard-[34]-of-4" || {
  echo "snakemake: the failure does not name the shard"; cat "$work/failed.log"; exit 1; }
grep -Eq "[34]-of-4" "$mark"/walk/train-shard-[34]-of-4.log || {
  echo "snakemake: the shard's log does not name the bad folder"; cat "$mark"/walk/train-shard-[34]-of-4.log; exit 1; }

# Repaired, the workflow resumes; the finished shards are not run again.
rm "${keydir}3-of-4" "${keydir}4-of-4"
smk >"$work/resumed.log" 2>&1 || { cat "$work/resumed.log"; exit 1; }
[ "$before" = "$(stamps)" ] || { echo "snakemake: finished shards were run again"; exit 1; }

"$python" tests/snakemake_check.py "$direct/sharded/run.json" "$work/runs/sharded/run.json" \
  "$direct_reports/sharded/report.md" "$work/reports/sharded/report.md"

# Rounds of the planner's own data run in the workflow too, to the same
# artifacts.
rounds=tests/data/planned-rounds.toml
"$alnlab" -q run "$rounds" --out "$direct" --reports "$direct_reports" >/dev/null
"$alnlab" export snakemake "$rounds" -o "$work/wf-rounds" \
  --out "$work/runs" --reports "$work/reports" --alnlab "$alnlab" >/dev/null
"$snakemake" --snakefile "$work/wf-rounds/Snakefile" --directory "$work/wf-rounds" --cores 2 \
  >"$work/rounds.log" 2>&1 || { cat "$work/rounds.log"; exit 1; }
grep -q "planning@2" "$work/runs/planned-rounds/run.json" || {
  echo "snakemake: the workflow's run record lacks round 2"; exit 1; }
"$python" tests/snakemake_check.py "$direct/planned-rounds/run.json" \
  "$work/runs/planned-rounds/run.json" "$direct_reports/planned-rounds/report.md" \
  "$work/reports/planned-rounds/report.md"
