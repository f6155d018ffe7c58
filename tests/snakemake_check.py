"""Checks that a run made by the exported Snakemake workflow equals the same
manifest run by `alnlab run`: every artifact byte for byte (the measured
columns of the training log and the timings aside), and every error table of
the report.

Usage: python snakemake_check.py DIRECT_RUN_JSON WORKFLOW_RUN_JSON DIRECT_REPORT WORKFLOW_REPORT
(run by tests/snakemake.sh)."""

import json
import sys

import pyarrow.parquet as pq

# The only values that differ between equal runs: measurements.
MEASURED = {
    "training": ["seconds"],
    "timings": ["ns_per_state", "ns_min", "ns_max", "ns_runs"],
    "planning": ["ms_per_decision", "ms_min", "ms_max"],
}


def artifacts(path):
    record = json.load(open(path))
    return {
        (v["name"], role): a["path"]
        for v in record["variants"]
        for role, a in v["artifacts"].items()
    }


def same_table_but(a, b, columns):
    """Equal tables but for the measured `columns` a table has (a
    piecewise-linear model's training log, rounds of splits, has no time)."""
    ta, tb = pq.read_table(a), pq.read_table(b)
    measured = [c for c in columns if c in ta.column_names]
    assert ta.column_names == tb.column_names, (a, b)
    # Row by row, a NaN (a reference policy's one-step error) equal to NaN.
    same = lambda x, y: x == y or (x != x and y != y)
    rows_a, rows_b = ta.drop_columns(measured).to_pylist(), tb.drop_columns(measured).to_pylist()
    return len(rows_a) == len(rows_b) and all(
        ra.keys() == rb.keys() and all(same(ra[k], rb[k]) for k in ra) for ra, rb in zip(rows_a, rows_b)
    )


def error_tables(report):
    """The report's lines that hold errors, not times: the §4.6 group tables,
    the variables worse than persistence, the histogram, the closed loop."""
    keep, lines = False, []
    for line in open(report, encoding="utf-8"):
        if line.startswith("#"):
            keep = any(
                title in line
                for title in ("Error by group", "Worse than persistence", "Error histogram", "Closed loop")
            )
        if keep:
            lines.append(line)
    return lines


def main(direct_json, workflow_json, direct_report, workflow_report):
    direct, workflow = artifacts(direct_json), artifacts(workflow_json)
    assert direct.keys() == workflow.keys(), (sorted(direct), sorted(workflow))
    for (variant, role), path in sorted(direct.items()):
        other = workflow[(variant, role)]
        # A round's table (`planning@2`) measures what its first does.
        measured = MEASURED.get(role.split("@")[0])
        if measured:
            assert same_table_but(path, other, measured), (variant, role)
        else:
            assert open(path, "rb").read() == open(other, "rb").read(), (variant, role, path, other)
    a, b = error_tables(direct_report), error_tables(workflow_report)
    assert a == b and len(a) > 20, "the reports' error tables differ"
    print(f"snakemake: {len(direct)} artifacts equal to alnlab run's; {len(a)} report lines equal")


if __name__ == "__main__":
    main(*sys.argv[1:])
