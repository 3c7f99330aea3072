#!/usr/bin/env python3
"""The analysis on its two derivations, same binary, same run: automatic
differentiation in-process (the default) against the symbolic IR derived by
symbolica in a child process (KINEGEN_ANALYSIS_DERIVER=symbolic, the analysis
before issue 71), on a user's spec the checkout does not bundle and on the
real logs in ../shared/real (or $KINEGEN_REAL_DATA).

For each command: wall and CPU seconds of each side (best of --reps, the
symbolic side with a warm derivation cache, as a user's second run has it),
their ratio, and the largest relative difference of any figure in the two
JSON documents (timings aside). Prints a Markdown table; --json writes it.

Usage: scripts/bench_derivers.py [--bin target/debug/kinegen] [--reps 3] [--json out.json]
"""
import argparse, json, os, resource, subprocess, sys, tempfile, time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# A velocity-commanded robot with a camera and a differential drive in
# encoder ticks, as users write them (not bundled: each is derived).
CART = (ROOT / "tests" / "output_shape.rs").read_text().split('const CART: &str = r#"')[1].split('"#;')[0]
WHEELIE = """name = "wheelie"
state = ["x", "y", "theta"]
[[input]]
name = "right_ticks"
column = "enc_r"
kind = "cumulative"
unit = "tick"
[[input]]
name = "left_ticks"
column = "enc_l"
kind = "cumulative"
unit = "tick"
[[parameter]]
name = "radius_right"
nominal = 0.042
min = 0.02
max = 0.08
[[parameter]]
name = "radius_left"
nominal = 0.042
min = 0.02
max = 0.08
[[parameter]]
name = "track"
nominal = 0.205
min = 0.1
max = 0.4
[[parameter]]
name = "ticks_per_wheel_rev"
nominal = 2796.8
const = true
[[define]]
name = "wr"
expr = "2*pi*right_ticks/ticks_per_wheel_rev"
[[define]]
name = "wl"
expr = "2*pi*left_ticks/ticks_per_wheel_rev"
[motion]
vx = "(radius_right*wr + radius_left*wl)/2"
vy = "0"
omega = "(radius_right*wr - radius_left*wl)/track"
"""


def figures(a, b, out, path=""):
    """Largest relative difference of the numbers in two JSON documents
    (relative to the larger of the two, or to 1e-9)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in set(a) | set(b):
            if k == "timing" or "elapsed" in k:
                continue  # how long it took, not what it found
            if k in a and k in b:
                figures(a[k], b[k], out, f"{path}/{k}")
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            figures(x, y, out, f"{path}[{i}]")
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if a != b:
            # figures at rounding level (an improvement of -3e-14) are
            # judged against 1e-9, not against themselves
            rel = abs(a - b) / max(abs(a), abs(b), 1e-9)
            if rel > out[0]:
                out[0], out[1] = rel, path


def run(binary, args, cwd, env):
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run([binary] + args + ["--json", "-"], cwd=cwd, env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if p.returncode != 0:
        sys.exit(f"{' '.join(args)}: exit {p.returncode}: {p.stderr.strip()[-400:]}")
    return wall, cpu, json.loads(p.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=str(ROOT / "target/debug/kinegen"))
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--json")
    a = ap.parse_args()
    real = Path(os.environ.get("KINEGEN_REAL_DATA", ROOT.parent / "shared" / "real"))
    if not real.is_dir():
        sys.exit(f"SKIPPED: no real logs at {real}")
    work = Path(tempfile.mkdtemp())
    (work / "cart.toml").write_text(CART)
    (work / "wheelie.toml").write_text(WHEELIE)
    robot = real / "mrclam-dataset6" / "robot3"
    seen = ["--observations", str(robot / "observations.csv"), "--landmarks", str(robot / "landmarks.csv")]
    square = sorted((real / "optiodom-dev").glob("diff-square-*"))[0]
    runs = ["--data", str(square / "run-01.csv"), "--data", str(square / "run-04.csv")]
    cases = [
        ("fit", "wheelie, OptiOdom square, 2 runs", ["fit", "--spec", "wheelie.toml"] + runs),
        ("diagnose", "wheelie, OptiOdom square, 2 runs", ["diagnose", "--spec", "wheelie.toml"] + runs),
        ("fit", "cart, MRCLAM robot 3", ["fit", "--spec", "cart.toml", "--data", str(robot / "log.csv")] + seen),
        ("diagnose", "cart, MRCLAM robot 3", ["diagnose", "--spec", "cart.toml", "--data", str(robot / "log.csv")] + seen),
        ("localize", "cart, MRCLAM robot 3", ["localize", "--spec", "cart.toml", "--data", str(robot / "log.csv")] + seen),
    ]
    rows = []
    for cmd, what, args in cases:
        best = {}
        docs = {}
        for rep in range(a.reps + 1):
            for side in ("symbolic", "autodiff"):
                env = dict(os.environ, KINEGEN_ANALYSIS_DERIVER=side)
                wall, cpu, doc = run(a.bin, args, work, env)
                docs[side] = doc
                if rep == 0:
                    continue  # warms the symbolic side's derivation cache
                w, c = best.get(side, (1e9, 1e9))
                best[side] = (min(w, wall), min(c, cpu))
        worst = [0.0, ""]
        figures(docs["symbolic"], docs["autodiff"], worst)
        (sw, sc), (aw, ac) = best["symbolic"], best["autodiff"]
        rows.append({"command": cmd, "case": what, "symbolic_wall_s": sw, "autodiff_wall_s": aw,
                     "symbolic_cpu_s": sc, "autodiff_cpu_s": ac, "wall_ratio": aw / sw,
                     "max_relative_difference": worst[0], "where": worst[1]})
        print(f"{cmd} ({what}): {sw:.2f} -> {aw:.2f} s wall (x{aw / sw:.2f}), "
              f"largest figure difference {worst[0]:.1e} at {worst[1]}", file=sys.stderr)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    print(f"\n{time.strftime('%Y-%m-%d')}, commit {commit}, {os.cpu_count()} cores, best of {a.reps}; "
          "`scripts/bench_derivers.py`\n")
    print("| command | case | symbolic s | autodiff s | ratio | largest figure difference |")
    print("|---|---|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['command']} | {r['case']} | {r['symbolic_wall_s']:.2f} | {r['autodiff_wall_s']:.2f} "
              f"| {r['wall_ratio']:.2f} | {r['max_relative_difference']:.1e} |")
    if a.json:
        Path(a.json).write_text(json.dumps({"commit": commit, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
