"""`Model.step` over a million rows from Python against the same loop in Rust.

Both sides run in this session on the same inputs: the Python package's
vectorised `step` (one call over (N, 3), (N, inputs) and (N,) arrays, the
loop in Rust with the GIL released), and `analysis/examples/step_rows.rs`, a
Rust program that derives the same spec and calls the library once a row,
built in the profile `pip install ./python` builds the extension in (dev).
Prints both medians, their ratio and that the results agree.

Usage, from the workspace root after `pip install ./python`:
    python3 python/examples/bench_step.py [SPEC] [--rows N] [--reps K]
"""
import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np

import kinegen

ROOT = Path(__file__).resolve().parents[2]


def sequence(n, offset, scale):
    """step_rows.rs's `input`: scale * (frac((k + offset) * 0.61803398875) - 0.5)."""
    k = np.arange(n, dtype=np.float64) + offset
    return scale * (np.modf(k * 0.61803398875)[0] - 0.5)


def python_side(spec, rows, reps):
    m = kinegen.Model.from_file(str(spec))
    nu = len(m.inputs)
    x = sequence(3 * rows, 0, 2.0).reshape(rows, 3)
    u = sequence(nu * rows, 7, 6000.0).reshape(rows, nu)
    dt = 0.105 + sequence(rows, 3, 0.19)
    times = []
    for _ in range(reps):
        started = time.perf_counter()
        out = m.step(x, u, dt)
        times.append((time.perf_counter() - started) * 1e9 / rows)
    return float(np.median(times)), float(out.sum())


def rust_side(spec, rows, reps):
    cmd = ["cargo", "run", "--quiet", "-p", "kinegen-analysis", "--example", "step_rows", "--",
           str(spec), str(rows), str(reps)]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec", nargs="?", default=str(ROOT / "spec" / "diff_drive.toml"))
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--markdown", action="store_true",
                    help="print one row of the guide's table (results/speed.md) instead")
    a = ap.parse_args()
    rust = rust_side(a.spec, a.rows, a.reps)
    py_ns, py_sum = python_side(a.spec, a.rows, a.reps)
    ratio = py_ns / rust["ns_per_row"]
    agree = abs(py_sum - rust["checksum"]) <= 1e-9 * max(1.0, abs(py_sum))
    if not agree:
        raise SystemExit(f"the two sides disagree: {py_sum} against {rust['checksum']}")
    if a.markdown:
        print(f"| {Path(a.spec).name} | {a.rows} | {py_ns:.1f} | {rust['ns_per_row']:.1f} | {ratio:.2f} |")
        return
    print(f"step over {a.rows} rows of {Path(a.spec).name}, median of {a.reps}")
    print(f"  Python Model.step   {py_ns:8.1f} ns a row")
    print(f"  Rust, the same loop {rust['ns_per_row']:8.1f} ns a row")
    print(f"  ratio {ratio:.2f} (the issue asks for at most 2); the results agree")


if __name__ == "__main__":
    main()
