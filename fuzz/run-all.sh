#!/usr/bin/env bash
# Fuzzes every reader of untrusted bytes, one target after another, and
# prints a line of figures per target (the table in fuzz/README.md).
#
# Usage (from the repository's root, with a nightly toolchain and
# `cargo install cargo-fuzz`):
#   fuzz/run-all.sh RUNS_DIR [SECONDS [TARGET…]]
# RUNS_DIR is an `alnlab run --out` folder whose files seed the corpora
# (files of at most 1 MiB: larger ones slow every execution); SECONDS per
# target (default 600). Corpora, findings and logs stay under fuzz/
# (ignored by git): corpus/<target>/, artifacts/<target>/, logs/<target>.log.
set -euo pipefail
runs=$(realpath "$1")
seconds=${2:-600}
shift $(( $# < 2 ? $# : 2 ))
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(manifest state_log parquet_table model run_record)
cd "$(dirname "$0")"

seed() { # seed TARGET FILE…: copy the files of at most 1 MiB, named by content
  mkdir -p "corpus/$1"
  local target=$1
  shift
  for f in "$@"; do
    [ -f "$f" ] && [ "$(stat -c %s "$f")" -le 1048576 ] || continue
    cp "$f" "corpus/$target/$(sha1sum "$f" | cut -c1-16)"
  done
}
shopt -s nullglob
seed manifest ../experiments/*.toml ../tests/data/*.toml
seed state_log "$runs"/cache/simulate/*/trajectory.mcap "$runs"/cache/plan/*/episodes.mcap
seed parquet_table "$runs"/cache/*/*/*.parquet
seed model "$runs"/cache/train/*/model.aln
seed run_record "$runs"/*/records/*.json

mkdir -p logs
cargo +nightly fuzz build -O
for t in "${targets[@]}"; do
  # Parquet's Thrift skipping can be slow on crafted headers (see README):
  # log such inputs as slow rather than stop the run.
  extra=()
  [ "$t" = parquet_table ] && extra=(-timeout=1200)
  status=0
  cargo +nightly fuzz run "$t" -O -- -max_total_time="$seconds" -rss_limit_mb=4096 \
    -print_final_stats=1 "${extra[@]}" >"logs/$t.log" 2>&1 || status=$?
  runs_done=$(grep -oE 'stat::number_of_executed_units: [0-9]+' "logs/$t.log" | grep -oE '[0-9]+$' || echo 0)
  last=$(grep -E '^#[0-9]+.*cov: ' "logs/$t.log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+' <<<"$last" | grep -oE '[0-9]+' || echo "?")
  ft=$(grep -oE 'ft: [0-9]+' <<<"$last" | grep -oE '[0-9]+' || echo "?")
  corp=$(grep -oE 'corp: [0-9]+' <<<"$last" | grep -oE '[0-9]+' || echo "?")
  found=$(ls "artifacts/$t" 2>/dev/null | wc -l)
  echo "$t: ${seconds} s, exit $status, $runs_done executions, cov $cov, ft $ft, corpus $corp, findings $found"
done
