"""Reads back, with MLflow's own Python client, what `alnlab export mlflow`
put on a tracking server, and compares it with the run record.

    python tests/mlflow_check.py RUN_JSON TRACKING_URI

Checks, for every variant and replicate of the record: exactly one active
MLflow run (so exporting twice did not duplicate), its parameters equal to
the record's (every one, nothing else), every metric value and series equal
to the record's (every one, nothing else; a series by step), the tags, and
the artifacts (the record itself and the report with its charts).
"""

import json
import re
import sys
import tempfile

from mlflow.tracking import MlflowClient


def key(name):
    """alnlab's rule: MLflow names keep letters, digits and `_-./: `."""
    return re.sub(r"[^A-Za-z0-9_\-./: ]", "_", name)


def main(record_path, uri):
    record = json.load(open(record_path))
    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name(record["experiment"])
    assert experiment is not None, f"no MLflow experiment {record['experiment']}"
    runs = client.search_runs(
        [experiment.experiment_id],
        filter_string=f"tags.`alnlab.run_id` = '{record['id']}'",
    )
    assert len(runs) == len(record["variants"]), (
        f"{len(runs)} MLflow runs for {len(record['variants'])} variant replicates"
    )
    checked = {"params": 0, "values": 0, "steps": 0, "artifacts": 0}
    for variant in record["variants"]:
        mine = [
            r
            for r in runs
            if r.data.tags.get("alnlab.variant") == variant["name"]
            and r.data.tags.get("alnlab.replicate") == str(variant["replicate"] + 1)
        ]
        assert len(mine) == 1, f"{variant['name']}: {len(mine)} MLflow runs"
        run = mine[0]
        name = f"{variant['name']} #{variant['replicate'] + 1}"
        assert run.info.status == "FINISHED", (name, run.info.status)
        tags = run.data.tags
        assert tags["mlflow.source.git.commit"] == (record["git_commit"] or ""), name
        assert tags["alnlab.manifest_sha256"] == record["manifest_sha256"], name
        assert tags["alnlab.export"] == "complete", name

        expected = {key(k): v for k, v in variant["parameters"].items()}
        assert expected, f"{name}: the record has no parameters"
        assert run.data.params == expected, f"{name}: parameters differ"
        checked["params"] += len(expected)

        metrics = variant["metrics"]
        names = {key(k) for k in metrics["values"]} | {key(k) for k in metrics["steps"]}
        assert set(run.data.metrics) == names, (
            f"{name}: metric names differ: "
            f"{sorted(set(run.data.metrics) ^ names)[:10]}"
        )
        for metric, value in metrics["values"].items():
            history = client.get_metric_history(run.info.run_id, key(metric))
            assert [(h.step, h.value) for h in history] == [(0, value)], (
                name,
                metric,
                [(h.step, h.value) for h in history],
                value,
            )
            checked["values"] += 1
        for metric, series in metrics["steps"].items():
            history = sorted(
                (h.step, h.value)
                for h in client.get_metric_history(run.info.run_id, key(metric))
            )
            assert history == [tuple(p) for p in series], (name, metric, history, series)
            checked["steps"] += len(series)

        listed = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert {"run.json", "report"} <= listed, (name, listed)
        report = {a.path for a in client.list_artifacts(run.info.run_id, "report")}
        assert {"report/report.md", "report/report.html"} <= report, (name, report)
        assert any(p.endswith(".svg") for p in report), (name, report)
        with tempfile.TemporaryDirectory() as tmp:
            local = client.download_artifacts(run.info.run_id, "run.json", tmp)
            exported = json.load(open(local))
        assert exported == record, f"{name}: the exported run.json differs from the record"
        checked["artifacts"] += 1 + len(report)
    print(
        f"MLflow round trip: {len(runs)} runs, {checked['params']} parameters, "
        f"{checked['values']} metric values, {checked['steps']} series points, "
        f"{checked['artifacts']} artifacts equal to the run record"
    )


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
