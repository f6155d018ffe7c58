"""Runs found from Python as the CLI finds them: models by experiment name,
id and folder; every record as a table; stage tables checked against the
record."""

import json
import shutil
import subprocess

import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

import alnlab


def test_load_finds_the_model_the_run_recorded(runs, quickstart, artifacts):
    found = artifacts("piecewise")
    by_paths = alnlab.Model(found["model"], found["codebook"])
    run_id = quickstart["id"]
    for model in [
        alnlab.load("quickstart", variant="piecewise", out=runs),
        alnlab.load(f"{run_id}:piecewise", out=runs),
        alnlab.load(run_id[:17], variant="piecewise", out=runs),
        alnlab.load(runs / "quickstart", variant="piecewise"),
    ]:
        assert repr(model) == repr(by_paths)
        assert model.state_names == by_paths.state_names
    second = alnlab.load("quickstart", variant="piecewise", replicate=2, out=runs)
    assert repr(second) != repr(by_paths)


def test_runs_lists_every_variant_and_replicate_with_parameters_and_metrics(runs, quickstart):
    table = alnlab.runs(runs)
    mine = table.filter(pc.equal(table.column("id"), quickstart["id"]))
    assert mine.num_rows == len(quickstart["variants"]) == 9
    rows = mine.to_pylist()
    for row, v in zip(rows, quickstart["variants"]):
        assert (row["variant"], row["replicate"], row["seed"]) == (v["name"], v["replicate"] + 1, v["seed"])
        assert row["param.train.model"] == v["parameters"]["train.model"]
        for name, value in v["metrics"]["values"].items():
            assert row[f"metric.{name}"] == value
    frame = alnlab.runs(runs, pandas=True)
    assert len(frame) == table.num_rows


def test_record_is_the_run_json(runs, quickstart):
    assert alnlab.record("quickstart", out=runs) == quickstart


def test_a_table_is_the_recorded_file_and_a_damaged_one_is_refused(runs, quickstart, tmp_path):
    got = alnlab.table("quickstart", "summary", variant="walk", out=runs)
    path = next(v for v in quickstart["variants"] if v["name"] == "walk")["artifacts"]["summary"]["path"]
    assert got.equals(pq.read_table(path))
    # A copy of the runs folder whose summary file changed by one byte.
    copy = tmp_path / "runs"
    shutil.copytree(runs / "quickstart", copy / "quickstart")
    summary = tmp_path / "summary.parquet"
    data = bytearray(open(path, "rb").read())
    data[100] ^= 1
    summary.write_bytes(bytes(data))
    for file in [copy / "quickstart" / "run.json", *(copy / "quickstart" / "records").glob("*.json")]:
        record = json.loads(file.read_text())
        for v in record["variants"]:
            v["artifacts"]["summary"]["path"] = str(summary)
        file.write_text(json.dumps(record))
    with pytest.raises(alnlab.DamagedError, match=r"summary.parquet: damaged: its sha256 is not the one run"):
        alnlab.table("quickstart", "summary", variant="walk", out=copy)


def test_runs_errors_are_the_cli_messages(runs, alnlab_bin):
    with pytest.raises(alnlab.InputError) as raised:
        alnlab.load("no-such-experiment", out=runs)
    cli = subprocess.run(
        [alnlab_bin, "runs", "show", "no-such-experiment", "--out", runs], capture_output=True, text=True
    )
    assert cli.returncode == 2 == raised.value.exit_code
    # The CLI's message, spelled for Python: what lists the runs is
    # `alnlab.runs(out=…)`, not the command.
    python = f'`alnlab.runs(out="{runs}")`'
    assert python in str(raised.value)
    spelled = str(raised.value).replace(python, f"`alnlab runs list --out {runs}`")
    assert f"error: {spelled}" in cli.stderr.splitlines()
    with pytest.raises(alnlab.InputError, match="differ; choose one with variant= and replicate= "):
        alnlab.load("quickstart", out=runs)
    with pytest.raises(alnlab.InputError, match="has no variant `nope`; it has: walk, gray, piecewise"):
        alnlab.load("quickstart:nope", out=runs)
    with pytest.raises(alnlab.InputError, match="no `model.aln` artifact; it has .*predictions"):
        alnlab.table("quickstart", "model.aln", variant="walk", out=runs)
    with pytest.raises(alnlab.InputError, match="`trajectory` is not a table"):
        alnlab.table("quickstart", "trajectory", variant="walk", out=runs)

    for replicate in (0, -1):
        with pytest.raises(alnlab.InputError, match=f"^replicate: expected a whole number of at least 1, got {replicate}"):
            alnlab.load("quickstart", variant="walk", replicate=replicate, out=runs)
    with pytest.raises(alnlab.InputError, match="model: expected one of aln, linear, boosted, got 'forest'"):
        alnlab.load("quickstart", variant="walk", out=runs, model="forest")
    with pytest.raises(alnlab.InputError, match=r"boosted.parquet: holds no boosted trees: .*\[test\] peer = true"):
        alnlab.load("quickstart", variant="walk", out=runs, model="boosted")
    linear = alnlab.load("quickstart", variant="piecewise", out=runs, model="linear")
    assert repr(linear).startswith("Model(piecewise-linear,") and repr(linear).endswith("linear.aln)")
