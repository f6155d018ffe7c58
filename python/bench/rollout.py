"""How fast a model rolls out through Python, beside the Rust batched path.

Times `Model.rollout` of B starts over H frames (logged states of the run's
pairs, controls drawn from the logged ones) on one thread, interleaved with
the same rollout on Rust-owned columns timed inside Rust
(`_alnlab.reference_rollout_ns`: the plan stage's batched path), each pair's
ratio with the median and range over `--repeat` pairs; and a one-state
`predict` call's time beside the same state through the Rust one-row path
(`_alnlab.reference_predict_ns`), each pair's difference being the call's
overhead. Prints JSON with --json.

Example:
    python python/bench/rollout.py target/xtask/runs/quickstart/run.json \\
        --variant piecewise --json
"""

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

# NumPy's BLAS threads spin for a while after its calls, on the cores the
# timed paths need: one thread is what is measured.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

import alnlab  # noqa: E402
from alnlab import _alnlab  # noqa: E402


def spread(samples: list[float]) -> dict:
    return {"median": statistics.median(samples), "min": min(samples), "max": max(samples)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_json", type=Path, help="a run's run.json")
    parser.add_argument("--variant", default="piecewise", help="a piecewise-linear variant (default: piecewise)")
    parser.add_argument("--starts", type=int, default=256, help="B, states rolled out together (default: 256)")
    parser.add_argument("--frames", type=int, default=10, help="H, frames each (default: 10)")
    parser.add_argument("--repeat", type=int, default=21, help="timed pairs (default: 21, at least 5)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    args = parser.parse_args()
    if args.repeat < 5:
        parser.error("--repeat: at least 5 runs make a median")
    record = json.loads(args.run_json.read_text())
    found = next(
        (v["artifacts"] for v in record["variants"] if v["name"] == args.variant and v["replicate"] == 0), None
    )
    if found is None:
        parser.error(f"{args.run_json}: no variant `{args.variant}`")
    model = alnlab.Model(found["model"]["path"], found["codebook"]["path"])
    pairs = pq.read_table(found["pairs"]["path"])
    rng = np.random.default_rng(0)
    b, h = args.starts, args.frames
    rows = rng.integers(0, pairs.num_rows, size=b)
    x0 = np.column_stack([pairs.column(f"x.{n}").to_numpy()[rows] for n in model.state_names])
    logged = np.column_stack([pairs.column(f"x.{n}").to_numpy() for n in model.control_names])
    controls = logged[rng.integers(0, len(logged), size=b * h)].reshape(b, h, -1)

    # Each repeat times the Python call and the Rust path back to back, so a
    # pair shares the machine's state; the figures are the pairs' ratios
    # (rollout) and differences (one state), their medians and ranges.
    # A second Rust run beside each pair gives the machine's own noise: the
    # ratio of two runs of the same path.
    python_ns, rust_ns, again_ns = [], [], []
    for _ in range(args.repeat):
        start = time.perf_counter_ns()
        model.rollout(x0, controls, threads=1)
        python_ns.append((time.perf_counter_ns() - start) / (b * h))
        rust_ns.extend(_alnlab.reference_rollout_ns(model, x0, controls, repeats=1))
        again_ns.extend(_alnlab.reference_rollout_ns(model, x0, controls, repeats=1))
    ratios = [p / r for p, r in zip(python_ns, rust_ns)]
    noise = [a / r for a, r in zip(again_ns, rust_ns)]
    one_x, one_u = x0[0].copy(), controls[0, 0].copy()
    calls = 2000
    one_ns, one_rust_ns = [], []
    for _ in range(args.repeat):
        start = time.perf_counter_ns()
        for _ in range(calls):
            model.predict(one_x, one_u, threads=1)
        one_ns.append((time.perf_counter_ns() - start) / calls)
        one_rust_ns.extend(_alnlab.reference_predict_ns(model, one_x, one_u, calls=calls, repeats=1))
    overheads = [p - r for p, r in zip(one_ns, one_rust_ns)]
    result = {
        "model": model.kind,
        "variant": args.variant,
        "starts": b,
        "frames": h,
        "threads": 1,
        "repeats": args.repeat,
        "python_rollout_ns_per_state": spread(python_ns),
        "rust_batched_ns_per_state": spread(rust_ns),
        "python_over_rust": spread(ratios),
        "pairs_over_1_25": sum(r > 1.25 for r in ratios),
        "rust_over_rust": spread(noise),
        "one_state_predict_ns": spread(one_ns),
        "rust_one_row_ns": spread(one_rust_ns),
        "one_state_overhead_ns": spread(overheads),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        ratio, over = result["python_over_rust"], result["one_state_overhead_ns"]
        p, r = (result[k]["median"] for k in ("python_rollout_ns_per_state", "rust_batched_ns_per_state"))
        print(
            f"{b}×{h} rollout, one thread: Python {p:.0f} ns a state, Rust batched {r:.0f} ns; "
            f"pairs {ratio['median']:.2f}× ({ratio['min']:.2f}–{ratio['max']:.2f}), "
            f"{result['pairs_over_1_25']} of {args.repeat} above 1.25×; "
            f"Rust against itself {result['rust_over_rust']['median']:.2f}× "
            f"({result['rust_over_rust']['min']:.2f}–{result['rust_over_rust']['max']:.2f})"
        )
        print(
            f"one-state predict: {result['one_state_predict_ns']['median'] / 1000:.2f} µs a call, "
            f"{over['median'] / 1000:.2f} µs ({over['min'] / 1000:.2f}–{over['max'] / 1000:.2f}) "
            f"beyond the Rust one-row path's {result['rust_one_row_ns']['median'] / 1000:.2f} µs"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
