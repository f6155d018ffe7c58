"""The control headlines of every committed planning report, recomputed from
its `replicates.csv` with NumPy and SciPy, apart from the Rust that wrote
them.

A report that plans states on its first screen, per task, each forward
model's cost minus the nominal simulator's, paired replicate by replicate,
as "higher: +2.72 [+1.04, +4.41]" — in the table of plans within real time
(across every replicate) and in the table at each deadline (the nominal
simulator and the ALN picked on replicate 1, judged on the others).
`replicates.csv` holds each policy's mean episode cost and median ms a
decision in every replicate (`plan <task>: <model> <planner> <budget>
cost`, `… ms`). This check reads both tables' rows, finds the two
policies' figures, recomputes the mean difference and its 95% t-interval,
and asserts that every number shown is the recomputed one to the digits
shown, and the verdict word the interval's; at each deadline it also
makes the picks again — each model at its largest budget whose replicate-1
median fits, the lowest replicate-1 cost among the simulators and among
the ALNs — and asserts the table shows those. Where a feedback loop
on gravity compensation ran, the deadline picks are set against it in a
paragraph; the loop of the lower replicate-1 cost is made again and each
difference recomputed alike. A report with planning
tables but no figures is named as not checked (rendered before the figures
were written); the check fails unless some report is checked.

Usage: python tests/plan_headlines.py reports
"""

import csv
import math
import re
import sys
from pathlib import Path

import numpy as np
from scipy import stats

# "ALN (round 2) (`learned-planning`), cem (128 sequences)" or
# "simulator@1, cem (256 sequences)", with an optional " — …" tail.
LABEL = re.compile(
    r"^(?P<model>ALN(?: \(round (?P<round>\d+)\))?(?: \(`(?P<variant>[^`]+)`\))?|[\w@]+(?: \(round \d+\))?)"
    r", (?P<planner>[\w-]+) \((?P<budget>\d+) sequences\)"
)
DIFFERENCE = re.compile(r"^(?P<word>lower|higher|indistinguishable): (?P<mean>\S+) \[(?P<low>\S+), (?P<high>\S+)\]$")


def number(text: str) -> float:
    return float(text.replace("−", "-"))


def close(shown: str, value: float) -> bool:
    """Whether `shown` is `value` to the digits it shows."""
    text = shown.replace("−", "-").lstrip("+")
    mantissa = text.split("e")[0]
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    exponent = int(text.split("e")[1]) if "e" in text else 0
    return abs(float(text) - value) <= 0.5 * 10 ** (exponent - decimals) * (1 + 1e-9)


def figures(path: Path) -> dict[tuple[str, str], list[float]]:
    """(variant, figure) → each replicate's value."""
    out = {}
    with path.open() as f:
        for row in csv.DictReader(f):
            if row["figure"].startswith("plan "):
                out[(row["variant"], row["figure"])] = [float(v) for v in row["values"].split(";")]
    return out


def figure_of(label: str, task: str, table: dict, first_variant: str, variants: list[str]) -> list[float]:
    """The replicates' mean costs of the policy a first-screen label names."""
    m = LABEL.match(label)
    assert m, f"a label the check cannot read: {label!r}"
    model = m["model"]
    if model.startswith("ALN"):
        variant = m["variant"] or (variants[0] if len(variants) == 1 else None)
        assert variant, f"{label!r}: which variant's ALN?"
        name = "aln" + (f" (round {m['round']})" if m["round"] else "")
    else:
        variant, name = first_variant, model
    key = (variant, f"plan {task}: {name} {m['planner']} {m['budget']} cost")
    assert key in table, f"{label!r}: no figure {key} in replicates.csv"
    return table[key]


def interval(values: np.ndarray) -> tuple[float, float, float]:
    n = len(values)
    mean = float(values.mean())
    half = stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n)
    return mean, mean - half, mean + half


def shown_as(cell: str, differences: np.ndarray, where: str) -> None:
    """Asserts that `cell` ("higher: +2.72 [+1.04, +4.41]") shows the mean
    of `differences`, its 95% t-interval to the digits shown, and the
    verdict word the interval allows."""
    m = DIFFERENCE.match(cell)
    assert m, f"{where}: a difference the check cannot read: {cell!r}"
    mean, low, high = interval(differences)
    word = "lower" if high < 0 else "higher" if low > 0 else "indistinguishable"
    assert m["word"] == word, f"{where}: shown {m['word']}, recomputed {word} ({low}, {high})"
    for shown, value in [(m["mean"], mean), (m["low"], low), (m["high"], high)]:
        assert close(shown, value), f"{where}: shown {shown}, recomputed {value}"


def picks(table: dict, task: str, deadline: float, variants: list[str]) -> dict[str, tuple]:
    """The deadline table's picks, made again from replicates.csv: for the
    simulators and for the ALNs, the (variant, figure) of the lowest
    replicate-1 cost among each model's largest budget whose replicate-1
    median ms fits `deadline`."""
    zero = {v: table.get((v, f"plan {task}: zero torques cost")) for v in variants}
    same = [v for v in variants if zero[v] == zero[variants[0]]]
    policy = re.compile(rf"^plan {re.escape(task)}: (?P<model>.+) (?P<planner>[\w-]+) (?P<budget>\d+) ms$")
    best: dict[tuple, tuple[int, tuple]] = {}
    for (variant, figure), values in table.items():
        m = policy.match(figure)
        if not m or variant not in same or values[0] > deadline:
            continue
        model = m["model"]
        if not model.startswith("aln") and variant != variants[0]:
            continue
        method = (variant if model.startswith("aln") else "", model, m["planner"])
        budget = int(m["budget"])
        if method not in best or budget > best[method][0]:
            cost = (variant, f"plan {task}: {model} {m['planner']} {budget} cost")
            best[method] = (budget, cost)
    out = {}
    for kind, prefix in [("nominal", "simulator@"), ("aln", "aln")]:
        fitting = [cost for (_, model, _), (_, cost) in best.items() if model.startswith(prefix)]
        if fitting:
            out[kind] = min(fitting, key=lambda key: table[key][0])
    return out


def tables(report: str):
    """Each first-screen planning table: (task, header, rows as cells)."""
    lines = report.splitlines()
    for i, line in enumerate(lines):
        m = re.match(r"^\*\*(?:Planning `(?P<a>[^`]+)` within real time|`(?P<b>[^`]+)` at each deadline)\*\*", line)
        if not m:
            continue
        start = next(k for k in range(i + 1, len(lines)) if lines[k].startswith("|"))
        header = [c.strip() for c in lines[start].strip("|").split("|")]
        rows = []
        for row in lines[start + 2 :]:
            if not row.startswith("|"):
                break
            rows.append([c.strip() for c in row.strip("|").split("|")])
        yield m["a"] or m["b"], header, rows


FEEDBACK = re.compile(
    r"^\*\*Against the controls engineer's first try\*\*, the PI?D loop on the nominal model's "
    r"gravity compensation \((?P<loop>gravity-pi?d), .*? across those replicates — (?P<picks>.*)\.$"
)
PICK = re.compile(r"^(?:at (?P<deadline>[\d.]+) ms, )?(?P<label>.+?) (?P<word>lower|higher|indistinguishable): (?P<interval>.+)$")


def check_feedback(report_dir: Path, report: str, table: dict, first_variant: str, variants: list[str]) -> int:
    """The deadline picks set against the feedback loop: the loop of the
    lower replicate-1 cost made again, and each pick's difference from it
    across replicates 2 on recomputed."""
    checked = 0
    task = None
    for line in report.splitlines():
        m = re.match(r"^\*\*`(?P<task>[^`]+)` at each deadline\*\*", line)
        if m:
            task = m["task"]
        m = FEEDBACK.match(line)
        if not m:
            continue
        assert task, f"{report_dir.name}: a feedback paragraph before any deadline table"
        loops = {name: table.get((first_variant, f"plan {task}: {name} cost")) for name in ["gravity-pd", "gravity-pid"]}
        ran = {name: values for name, values in loops.items() if values}
        assert ran, f"{report_dir.name}, `{task}`: a feedback paragraph but no loop's figures in replicates.csv"
        picked = min(ran, key=lambda name: ran[name][0])
        assert picked == m["loop"], f"{report_dir.name}, `{task}`: the loop shown is {m['loop']}, the lower in replicate 1 is {picked}"
        held = np.array(ran[picked])[1:]
        if m["picks"] == "none fits a deadline":
            continue
        for part in m["picks"].split("; "):
            p = PICK.match(part)
            assert p, f"{report_dir.name}: a pick the check cannot read: {part!r}"
            a = np.array(figure_of(p["label"], task, table, first_variant, variants))[1:]
            where = f"{report_dir.name}, `{task}`, {p['label']} − {picked}"
            shown_as(f"{p['word']}: {p['interval']}", a - held, where)
            checked += 1
    return checked


def check(report_dir: Path) -> int:
    csv_path = report_dir / "replicates.csv"
    table = figures(csv_path) if csv_path.exists() else {}
    planning_tables = list(tables((report_dir / "report.md").read_text()))
    if not planning_tables:
        return 0
    variants = list(dict.fromkeys(v for v, _ in table))
    checked = 0
    if not table:
        # Said, not failed: a report rendered before its planning figures
        # went into replicates.csv has nothing to check them against.
        print(f"{report_dir.name}: NOT CHECKED — planning tables but no plan figures in replicates.csv (rendered before they were written; run it again)")
        return 0
    first_variant = variants[0]
    for task, header, rows in planning_tables:
        label_at = 1 if header[0] == "deadline" else 0
        column = next(k for k, h in enumerate(header) if h.startswith("− "))
        nominal_of_table = header[column][2:]
        in_table = 0
        for k, row in enumerate(rows):
            cell = row[column]
            if cell == "—":
                continue
            # The deadline table's nominal simulator is the row before the
            # others of its deadline, the one whose difference is "—".
            if label_at:
                nominal = next(r[label_at] for r in rows[: k + 1][::-1] if r[0] == row[0] and r[column] == "—")
            else:
                nominal = nominal_of_table
            label = row[label_at].split(" — ")[0]
            a = np.array(figure_of(label, task, table, first_variant, variants))
            b = np.array(figure_of(nominal, task, table, first_variant, variants))
            if label_at:
                # Picked on replicate 1, judged on the others; the picks
                # made again.
                deadline = float(row[0].removesuffix(" ms"))
                again = picks(table, task, deadline, variants)
                assert table[again["nominal"]] == list(b), f"{report_dir.name}, `{task}` at {row[0]}: the nominal simulator shown is not the one the rule picks ({again['nominal']})"
                if "— the reference" not in row[label_at]:
                    assert table[again["aln"]] == list(a), f"{report_dir.name}, `{task}` at {row[0]}: the ALN shown is not the one the rule picks ({again['aln']})"
                a, b = a[1:], b[1:]
            shown_as(cell, a - b, f"{report_dir.name}, `{task}`, {label} − {nominal}")
            checked += 1
            in_table += 1
        assert in_table > 0, f"{report_dir.name}, `{task}`: a planning table with no difference to check"
    checked += check_feedback(report_dir, (report_dir / "report.md").read_text(), table, first_variant, variants)
    if checked:
        print(f"{report_dir.name}: {checked} planning differences recomputed from replicates.csv")
    return checked


def main() -> int:
    reports = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("reports")
    total = sum(check(d) for d in sorted(reports.iterdir()) if (d / "report.md").exists())
    assert total > 0, f"{reports}: no planning difference to recompute"
    return 0


if __name__ == "__main__":
    sys.exit(main())
