"""Standard readers must read what alnlab writes (docs/design.md §2).

Usage: python tests/interop.py RUN_JSON REPORT_DIR

Reads every Parquet artifact named in the run record with pyarrow and every
MCAP log with the `mcap` package, decoding each /state message with the ROS 2
decoder from the schema stored in the file, and checks the decoded values
against the stride stage's pairs table; checks that /tf and /scene use
Foxglove's well-known schema names and that every scene's model is in an
`alnlab.model` metadata record; recomputes every statistic of
summary.parquet from predictions.parquet in plain Python, and every paired
comparison of comparisons.parquet (mean difference, standard deviation and
95% t-interval) with numpy and scipy, and, for an experiment with
replicates, every figure of replicates.csv across replicates; parses every
SVG the report shows as XML. Exits non-zero on any mismatch.
"""

import csv
import functools
import json
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
from scipy import stats
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


@functools.lru_cache(maxsize=None)
def field_name(name: str) -> str:
    """The /state field of a variable, as alnlab names it: lower case, every
    character but letters and digits made `_`, runs of `_` one and none at
    either end, `f_` before one that does not start with a letter
    (`f_E.1.x` → `f_e_1_x`)."""
    field = re.sub(r"_+", "_", re.sub(r"[^a-z0-9]", "_", name.lower())).strip("_")
    return field if field[:1].isalpha() else "f_" + field


def quantile(xs, q):
    """numpy's default (linear) percentile of sorted xs."""
    pos = q * (len(xs) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


@functools.lru_cache(maxsize=1)
def prediction_columns(path: str) -> dict:
    """predictions.parquet's columns as Python lists, read once: the summary,
    the comparisons and the rollout are all recomputed from them."""
    columns = ["model", "variable", "row", "held_out", "true_level", "error"]
    table = pq.read_table(path, columns=columns)
    return {c: table.column(c).to_pylist() for c in columns}


def check_summary(predictions_path, summary_path):
    """Every statistic of summary.parquet, recomputed from the predictions,
    over all test rows and over the held-out ones."""
    errors = defaultdict(list)
    truth = defaultdict(list)
    cols = prediction_columns(predictions_path)
    columns = ["model", "variable", "held_out", "true_level", "error"]
    for model, variable, held_out, true_level, error in zip(*(cols[c] for c in columns)):
        for rows in ["all"] + (["held-out"] if held_out else []):
            errors[(rows, model, variable)].append(error)
            truth[(rows, model, variable)].append(true_level)
    summary = pq.read_table(summary_path).to_pylist()
    assert len(summary) == len(errors), (len(summary), len(errors))
    for row in summary:
        key = (row["rows"], row["model"], row["variable"])
        assert math.isclose(row["true_std_dev"], float(np.std(truth[key], ddof=1)), rel_tol=1e-9, abs_tol=1e-12), key
        xs = sorted(errors[key])
        n = len(xs)
        mean = sum(xs) / n
        std = math.sqrt(sum((x - mean) ** 2 for x in xs) / (n - 1)) if n > 1 else float("nan")
        cut = n * 5 // 100
        trimmed = sum(xs[cut:n - cut]) / (n - 2 * cut)
        expected = {
            "n": n, "mean": mean, "std_dev": std, "std_err": std / math.sqrt(n),
            "trimmed_mean": trimmed, "median": quantile(xs, 0.5),
            "iqr": quantile(xs, 0.75) - quantile(xs, 0.25), "p95": quantile(xs, 0.95), "max": xs[-1],
        }
        for key, value in expected.items():
            assert math.isclose(row[key], value, rel_tol=1e-9, abs_tol=1e-12), (row["variable"], key, row[key], value)
        edges = list(range(11)) + [20, 50, 100, max(100, xs[-1]) + 1]
        counts, _ = np.histogram(xs, bins=edges)
        names = [f"hist_{k}" for k in range(10)] + ["hist_10_19", "hist_20_49", "hist_50_99", "hist_100_plus"]
        assert counts.tolist() == [row[name] for name in names], row["variable"]
    return len(summary)


def check_comparisons(predictions_path, comparisons_path):
    """Every paired comparison, recomputed with numpy and scipy: the ALN's
    errors minus the other model's on the same rows, per variable and
    averaged over the variables per row; mean, sample standard deviation
    and the 95% t-interval agree to 1e-9."""
    cols = prediction_columns(predictions_path)
    errors = defaultdict(list)
    held = {}
    for m, v, r, h, e in zip(cols["model"], cols["variable"], cols["row"], cols["held_out"], cols["error"]):
        errors[(m, v)].append((r, e))
        held[r] = h
    variables = sorted({v for _, v in errors}, key=cols["variable"].index)
    models = sorted({m for m, _ in errors}, key=cols["model"].index)
    rows = [r for r, _ in errors[(models[0], variables[0])]]
    err = {k: np.array([e for _, e in pairs], dtype=float) for k, pairs in errors.items()}
    sets = {"all": np.ones(len(rows), bool), "held-out": np.array([held[r] for r in rows])}

    def interval(d):
        n = len(d)
        mean = float(np.mean(d))
        sd = float(np.std(d, ddof=1))
        half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
        return n, mean, sd, mean - half, mean + half

    expected = {}
    for name, mask in sets.items():
        if not mask.any():
            continue
        for other in models:
            if other == "aln":
                continue
            per_variable = [err[("aln", v)][mask] - err[(other, v)][mask] for v in variables]
            for v, d in zip(variables, per_variable):
                expected[(name, other, v)] = interval(d)
            expected[(name, other, None)] = interval(np.mean(per_variable, axis=0))
    got = pq.read_table(comparisons_path).to_pylist()
    assert len(got) == len(expected), (len(got), len(expected))
    for row in got:
        n, mean, sd, low, high = expected[(row["rows"], row["against"], row["variable"])]
        assert row["n"] == n, row
        for key, value in [("mean_difference", mean), ("std_dev", sd), ("ci_low", low), ("ci_high", high)]:
            assert math.isclose(row[key], value, rel_tol=1e-9, abs_tol=1e-9), (row, key, value)
        verdict = ("tied" if mean == 0 and sd == 0 else "lower" if high < 0
                   else "higher" if low > 0 else "indistinguishable")
        assert row["verdict"] == verdict, (row, verdict)
    return len(got)


def check_rollout(predictions_path, rollout_path):
    """One step of the closed loop is the open-loop prediction: the rollout's
    first-step errors equal the predictions' for the same rows, for every
    model (the true levels come from the trajectory log, quantized anew)."""
    cols = prediction_columns(predictions_path)
    one_step = dict(zip(zip(cols["model"], cols["variable"], cols["row"]), cols["error"]))
    rollout = pq.read_table(rollout_path)
    first = rollout.filter(pc.equal(rollout.column("horizon"), 1)).to_pylist()
    assert first, "no rollout"
    for r in first:
        assert one_step[(r["model"], r["variable"], r["start"])] == r["error"], r
    return len(first)


def judged_figures(summary_path, comparisons_path):
    """One replicate's headline figures on its held-out rows (all rows when
    none is held out): mean errors over the variables of the ALN,
    persistence and linear, and the ALN's mean paired difference against
    the two baselines."""
    summary = pq.read_table(summary_path).to_pylist()
    rows = "held-out" if any(r["rows"] == "held-out" for r in summary) else "all"
    figures = {}
    for model in ["aln", "persistence", "linear"]:
        means = [r["mean"] for r in summary if r["rows"] == rows and r["model"] == model]
        figures[f"{model} mean"] = float(np.mean(means))
    for row in pq.read_table(comparisons_path).to_pylist():
        if row["rows"] == rows and row["model"] == "aln" and row["variable"] is None \
                and row["against"] in ("persistence", "linear"):
            figures[f"aln - {row['against']}"] = row["mean_difference"]
    return figures


def replicate_figures(artifacts):
    """judged_figures with the learned peer (boosted trees) where the test
    stage fitted one, and the ALN's mean error per variable."""
    summary_path, comparisons_path = artifacts["summary"]["path"], artifacts["comparisons"]["path"]
    figures = judged_figures(summary_path, comparisons_path)
    summary = pq.read_table(summary_path).to_pylist()
    rows = "held-out" if any(r["rows"] == "held-out" for r in summary) else "all"
    boosted = [r["mean"] for r in summary if r["rows"] == rows and r["model"] == "boosted"]
    if boosted:
        figures["boosted mean"] = float(np.mean(boosted))
        for row in pq.read_table(comparisons_path).to_pylist():
            if row["rows"] == rows and row["model"] == "aln" and row["variable"] is None \
                    and row["against"] == "boosted":
                figures["aln - boosted"] = row["mean_difference"]
    figures["by_variable"] = {r["variable"]: r["mean"] for r in summary
                              if r["rows"] == rows and r["model"] == "aln"}
    # Every other model's mean (the simulators), and each baseline's mean
    # minus persistence's: the first screen's rows.
    models = {r["model"] for r in summary if r["rows"] == rows}
    for model in models:
        means = [r["mean"] for r in summary if r["rows"] == rows and r["model"] == model]
        figures.setdefault(f"{model} mean", float(np.mean(means)))
    for model in models - {"aln", "persistence"}:
        figures[f"{model} mean - persistence mean"] = \
            figures[f"{model} mean"] - figures["persistence mean"]
    # The ALN against each simulator setting: the difference of the two
    # means over the same rows and variables (the stage pairs only the
    # headline baselines).
    for model in models - {"aln", "persistence", "linear", "boosted"}:
        figures[f"aln - {model}"] = figures["aln mean"] - figures[f"{model} mean"]
    return figures


def check_metrics(variant):
    """The run record's metrics, recomputed from the artifacts: the headline
    figures, every variable's mean error, the one-thread timings and the
    training errors per epoch. Returns how many were compared."""
    a = variant["artifacts"]
    metrics = variant["metrics"]
    values = metrics["values"]
    summary = pq.read_table(a["summary"]["path"]).to_pylist()
    rows = metrics["rows"]
    assert rows == ("held-out" if any(r["rows"] == "held-out" for r in summary) else "all")
    expected = {}
    # judged_figures names them "aln mean" and "aln - persistence".
    for label, figure in judged_figures(a["summary"]["path"], a["comparisons"]["path"]).items():
        if label.endswith(" mean"):
            expected[f"error/{label.removesuffix(' mean')}"] = figure
        else:
            expected[f"difference/{label.removeprefix('aln - ')}"] = figure
    for r in summary:
        if r["rows"] == rows:
            expected[f"error_by_variable/{r['model']}/{r['variable']}"] = r["mean"]
    for t in pq.read_table(a["timings"]["path"]).to_pylist():
        if t["threads"] == 1:
            expected[f"ns_per_state/{t['model']}/{t['path']}"] = t["ns_per_state"]
    for name, value in expected.items():
        assert math.isclose(values[name], value, rel_tol=1e-12, abs_tol=1e-12), (name, values[name], value)
    training = pq.read_table(a["training"]["path"])
    if "epoch" not in training.column_names:
        # A piecewise-linear model logs rounds of splits, not epochs.
        assert "training_error" not in metrics["steps"], "training errors of a piecewise model"
        return len(expected)
    per_epoch = {}
    for row in training.to_pylist():
        per_epoch.setdefault(row["epoch"], []).append(row["errors"])
    series = [[e, float(np.mean(v))] for e, v in sorted(per_epoch.items())]
    assert metrics["steps"]["training_error"] == series, "training errors per epoch"
    return len(expected) + len(series)


def check_replicates(record, report_dir):
    """replicates.csv: every figure's per-replicate values recomputed from
    each replicate's summary and comparisons, and their mean, standard
    deviation and 95% t-interval across replicates with numpy and scipy."""
    by_variant = defaultdict(list)
    for variant in record["variants"]:
        by_variant[variant["name"]].append(variant)
    if all(len(v) < 2 for v in by_variant.values()):
        return 0
    rows = list(csv.DictReader(open(Path(report_dir) / "replicates.csv")))
    checked = 0
    for name, replicates in by_variant.items():
        ordered = sorted(replicates, key=lambda r: r["replicate"])
        per = [replicate_figures(r["artifacts"]) for r in ordered]
        for row in (r for r in rows if r["variant"] == name):
            if row["figure"].startswith("aln mean - "):
                # "aln mean - B aln mean", or "… over N common variables":
                # means over the variables both variants' ALNs predict.
                other = row["figure"][len("aln mean - "):].split(" aln mean")[0]
                theirs = [replicate_figures(r["artifacts"])
                          for r in sorted(by_variant[other], key=lambda r: r["replicate"])]
                common = sorted(set(per[0]["by_variable"]) & set(theirs[0]["by_variable"]))
                if len(common) != len(per[0]["by_variable"]) or len(common) != len(theirs[0]["by_variable"]):
                    assert row["figure"].endswith(f" over {len(common)} common variables"), row
                values = np.array([
                    np.mean([p["by_variable"][v] for v in common]) - np.mean([q["by_variable"][v] for v in common])
                    for p, q in zip(per, theirs)])
            else:
                values = np.array([p[row["figure"]] for p in per])
            listed = [float(x) for x in row["values"].split(";")]
            assert np.allclose(listed, values, rtol=1e-12, atol=1e-12), (row, values)
            n = len(values)
            mean, sd = float(np.mean(values)), float(np.std(values, ddof=1))
            half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
            assert int(row["replicates"]) == n, row
            for key, value in [("mean", mean), ("std_dev", sd), ("ci_low", mean - half), ("ci_high", mean + half)]:
                assert math.isclose(float(row[key]), value, rel_tol=1e-9, abs_tol=1e-9), (row, key, value)
            checked += 1
        assert checked, f"{name}: no figure in replicates.csv"
    return checked


def check_report(report_dir):
    """The report exists and every chart it shows parses as an SVG document."""
    report = Path(report_dir) / "report.md"
    text = report.read_text()
    charts = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert charts, "the report shows no chart"
    for chart in charts:
        root = ET.parse(Path(report_dir) / chart).getroot()
        assert root.tag == "{http://www.w3.org/2000/svg}svg", (chart, root.tag)
    return len(charts)


def learned_variables(artifacts: dict) -> list:
    """The codebook's learned variables, in its order."""
    codebook = pq.read_table(artifacts["codebook"]["path"]).to_pylist()
    return [e["variable"] for e in codebook if e["learned"]]


def test_row_count(artifacts: dict) -> int:
    """The rows of the levels table the test stage predicts."""
    levels = pq.read_table(artifacts["levels"]["path"], columns=["split"]).column("split").to_pylist()
    return sum(1 for s in levels if s in ("test", "both"))


def check_circuit(artifacts: dict, report_dir: str) -> int:
    """The circuit stage's figures: three parts per learned variable, every
    test row simulated equal, and the longest path the report gives
    recomputed (the deepest variable's trees + votes + decoding)."""
    if "circuit" not in artifacts:
        return 0
    rows = pq.read_table(artifacts["circuit"]["path"]).to_pylist()
    if not rows:
        return 0
    learned = learned_variables(artifacts)
    assert [r["variable"] for r in rows[::3]] == learned, "one variable per learned one"
    assert [r["part"] for r in rows] == ["trees", "votes", "decode"] * len(learned)
    test = test_row_count(artifacts)
    assert all(r["rows_equal"] == test for r in rows), (rows[0]["rows_equal"], test)
    depth = max(sum(r["depth"] for r in rows[i:i + 3]) for i in range(0, len(rows), 3))
    report = open(os.path.join(report_dir, "report.md")).read()
    assert f"**{depth} gate levels**" in report, depth
    return len(rows)


def check_fpga(artifacts: dict, report_dir: str) -> int:
    """The place-and-route figures: one row per learned variable, its
    mapped netlist simulated equal on every test row, and the state's time
    the report gives recomputed (the slowest variable's critical path)."""
    if "fpga" not in artifacts:
        return 0
    rows = pq.read_table(artifacts["fpga"]["path"]).to_pylist()
    if not rows:
        return 0
    assert [r["variable"] for r in rows] == learned_variables(artifacts)
    test = test_row_count(artifacts)
    assert all(r["rows_equal"] == test for r in rows), (rows[0]["rows_equal"], test)
    assert all(r["luts"] <= r["logic_cells"] or r["critical_ns"] is None for r in rows)
    report = open(os.path.join(report_dir, "report.md")).read()
    quoted = [line.split("|") for line in report.splitlines() if line.startswith("| this forest on the ")]
    assert quoted, "no FPGA row in the report"
    if any(r["critical_ns"] is None for r in rows):
        # A variable does not fit: the state has no time, and the report says so.
        assert any(cells[4].strip() == "—" for cells in quoted), quoted
    else:
        state_ns = max(r["critical_ns"] for r in rows)
        assert any(abs(float(cells[4]) / state_ns - 1) < 0.005 for cells in quoted), (state_ns, quoted)
    return len(rows)


@functools.lru_cache(maxsize=None)
def decode_trajectory(path: str) -> dict:
    """Every /state message of the MCAP log at `path`, decoded with the
    schema stored in the file, by (scene, run, frame); checks the log's
    profile, Foxglove schema names, models and /tf on the way. Once a log:
    the variants of a replicate share theirs."""
    frames = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        assert schemas["/tf"] == "foxglove.FrameTransforms", schemas
        assert schemas["/scene"] == "foxglove.SceneUpdate", schemas
        models = [m for m in reader.iter_metadata() if m.name == "alnlab.model"]
        scenes = {c.metadata["scene"] for c in summary.channels.values() if c.topic == "/state"}
        assert {m.metadata["scene"] for m in models} == scenes, (models, scenes)
        for m in models:
            model = json.loads(m.metadata["json"])
            assert model["links"][0]["parent"] == -1 and model["conventions"]["units"] == "SI"
        tf = 0
        for _, channel, message in reader.iter_messages(topics=["/tf"]):
            transforms = json.loads(message.data)["transforms"]
            assert all(t["parent_frame_id"] == "world" for t in transforms)
            tf += 1
        assert tf > 0, "no /tf messages"
        for schema, channel, message, decoded in reader.iter_decoded_messages(topics=["/state"]):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            names = channel.metadata["variables"].split(",")
            values = {n: getattr(decoded, field_name(n)) for n in names}
            assert all(math.isfinite(v) for v in values.values())
            frames[(channel.metadata["scene"], decoded.run, decoded.frame)] = values
    assert frames, "no /state messages"
    return frames


def main(run_json: str, report_dir: str) -> int:
    record = json.load(open(run_json))
    checked = 0
    for variant in record["variants"]:
        artifacts = variant["artifacts"]
        for role, artifact in artifacts.items():
            path = artifact["path"]
            if path.endswith(".parquet"):
                table = pq.read_table(path)
                meta = pq.read_metadata(path).metadata
                # The plan stage plans nothing without [[plan.task]].
                # The circuit stage measures nothing without `synthesize`,
                # and places nothing without `fpga`. The test stage fits
                # boosted trees only with `peer`.
                assert table.num_rows > 0 or role in ("plan", "planning", "transitions", "transitions-nominal", "circuit", "fpga", "fixed", "boosted"), f"{path}: no rows"
                assert meta[b"alnlab.stage"], f"{path}: no provenance"
                assert json.loads(meta[b"alnlab.params"])["seed"] == variant.get("seed", record["seed"]), path
                checked += 1

        frames = decode_trajectory(artifacts["trajectory"]["path"])

        # Every pair row equals the decoded frames it was taken from.
        pairs = pq.read_table(artifacts["pairs"]["path"]).to_pylist()
        for row in pairs:
            x = frames[(row["scene"], row["run"], row["step"])]
            y = frames[(row["scene"], row["run"], row["step"] + 1)]
            for name in x:
                assert row["x." + name] == x[name], (row["step"], name)
                assert row["y." + name] == y[name], (row["step"], name)
        summaries = check_summary(artifacts["predictions"]["path"], artifacts["summary"]["path"])
        compared = check_comparisons(artifacts["predictions"]["path"], artifacts["comparisons"]["path"])
        rolled = check_rollout(artifacts["predictions"]["path"], artifacts["rollout"]["path"])
        metrics = check_metrics(variant)
        circuit = check_circuit(artifacts, report_dir)
        placed = check_fpga(artifacts, report_dir)
        print(f"{variant['name']}: {len(frames)} /state messages decoded, {circuit} circuit rows checked, "
              f"{placed} variables placed and routed checked, "
              f"{len(pairs)} pair rows match, {checked} Parquet files read, "
              f"{summaries} summary rows recomputed, {compared} paired comparisons recomputed, "
              f"{rolled} first rollout steps match, {metrics} record metrics recomputed")
    print(f"report: {check_report(report_dir)} SVG charts parse, "
          f"{check_replicates(record, report_dir)} figures across replicates recomputed")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
