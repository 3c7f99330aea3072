#!/usr/bin/env python3
"""High-precision reference for the exact step near its removable singularity.

diff_drive's `step_exact` and `step_exact_jac_p` (seed 003's exact integration
on SE(2)), evaluated with mpmath at 50 digits for omega*dt = s from 0 through
the series switch (0.05) to 1, written with the analytic forms
sin(s)/s = sinc(s) and (1 - cos s)/s = s/2 sinc(s/2)^2, which have no
cancellation at any s. `verify/tests/precision.rs` checks the generated
kernels against it (relative to each output row's scale).

It also writes atan2.json: atan2(y, x) at 50 digits on 2,800 points (every
octant, radii from 1e-3 to 1e3, the generated crate's reduction cuts, the
axes, the branch cut at pi and one-argument atan points), each as the double
nearest the true value plus the remainder, so that the test can measure the
generated crate's atan2 and libm's in fractions of an ulp. And sincos.json:
sin x and cos x at 50 digits on 3,000 points (headings in every quadrant,
small angles, arguments up to 1e7, and those within a hair of a multiple
of pi/2, where the reduction cancels), in the same form.

    python3 verify/precision/reference.py           # (re)write near_zero.json
    python3 verify/precision/reference.py --check   # fail if it differs
"""
import json
import math
import random
import sys
from pathlib import Path

import mpmath as mp

mp.mp.dps = 50
HERE = Path(__file__).resolve().parent
FIXTURE = HERE / "near_zero.json"
ATAN2_FIXTURE = HERE / "atan2.json"
SINCOS_FIXTURE = HERE / "sincos.json"
# spec/diff_drive.toml's nominal values: r_r, r_l, b, counts_per_rev, gear_ratio
PARAMS = [0.042, 0.042, 0.2, 64.0, 0.022883295194508008]
S_VALUES = [0.0, 1e-12, -1e-12, 1e-8, 1e-5, -1e-3, 0.02, 0.0499, 0.05, 0.0501, -0.0501, 0.2, 1.0]
DT = 0.05
N_L = 3000.0


def step(x, u, p, dt):
    r_r, r_l, b, counts, gear = p
    w_r = 2 * mp.pi * gear * u[0] * r_r / counts
    w_l = 2 * mp.pi * gear * u[1] * r_l / counts
    v, omega = (w_r + w_l) / 2, (w_r - w_l) / b
    s = omega * dt
    sinc_s = mp.sinc(s)
    cosc_s = s / 2 * mp.sinc(s / 2) ** 2
    bx, by = sinc_s * v * dt, cosc_s * v * dt
    th = x[2]
    return [
        x[0] + mp.cos(th) * bx - mp.sin(th) * by,
        x[1] + mp.sin(th) * bx + mp.cos(th) * by,
        th + s,
    ]


def case(s):
    # the right encoder rate that puts omega*dt at s (as an f64: the kernel's input)
    k = 2 * mp.pi * PARAMS[4] * PARAMS[0] / PARAMS[3]
    n_r = float(N_L + s * PARAMS[2] / (float(k) * DT))
    x, u = [0.3, -0.2, 0.7], [n_r, N_L]
    xs, us, ps = ([mp.mpf(t) for t in v] for v in (x, u, PARAMS))
    pose = step(xs, us, ps, mp.mpf(DT))
    jac_p = [
        [
            mp.diff(lambda q, i=i, j=j: step(xs, us, ps[:j] + [q] + ps[j + 1 :], mp.mpf(DT))[i], ps[j])
            for j in range(5)
        ]
        for i in range(3)
    ]
    text = lambda v: mp.nstr(v, 25)
    return {
        "s": s,
        "x": x,
        "u": u,
        "dt": DT,
        "pose": [text(v) for v in pose],
        "jac_p": [[text(v) for v in row] for row in jac_p],
    }


def atan2_points():
    """(y, x) pairs, from a fixed seed (Python's Mersenne Twister is stable
    across versions)."""
    rng = random.Random(2026)
    pts = []
    for _ in range(1200):  # any direction, any scale
        th, r = rng.uniform(-math.pi, math.pi), 10 ** rng.uniform(-3, 3)
        pts.append((r * math.sin(th), r * math.cos(th)))
    for _ in range(800):  # either side of each cut of the octant (q = y/x)
        q = rng.choice([0.4375, 0.6875, 1.1875, 2.4375]) * (1 + rng.uniform(-1e-3, 1e-3))
        x = rng.uniform(0.1, 10) * rng.choice([1, -1])
        pts.append((q * abs(x) * rng.choice([1, -1]), x))
    for _ in range(400):  # near the axes and the branch cut: y/x tiny or huge
        a, b = 10 ** rng.uniform(-12, -1), rng.uniform(0.5, 2)
        y, x = (a * rng.choice([1, -1]), b * rng.choice([1, -1]))
        pts.append((y, x) if rng.random() < 0.5 else (x, y))
    for _ in range(400):  # atan(v) = atan2(v, 1)
        pts.append((rng.uniform(-1, 1) * 10 ** rng.uniform(-3, 3), 1.0))
    return pts


def atan2_fixture():
    rows = []
    for y, x in atan2_points():
        ref = mp.atan2(mp.mpf(y), mp.mpf(x))
        hi = float(ref)
        # as text: serde_json's default float parsing may miss the nearest
        # double by an ulp, Rust's str::parse does not
        rows.append([repr(v) for v in (y, x, hi, float(ref - mp.mpf(hi)))])
    return {
        "doc": "atan2(y, x) at 50 digits: [y, x, nearest double, remainder] (verify/precision/reference.py)",
        "points": rows,
    }


def sincos_points():
    """Arguments x, from a fixed seed."""
    rng = random.Random(2027)
    pts = []
    for _ in range(1200):  # headings, any quadrant
        pts.append(rng.uniform(-4 * math.pi, 4 * math.pi))
    for _ in range(600):  # small angles: a step's turn, a steering angle
        pts.append(rng.choice([1, -1]) * 10 ** rng.uniform(-12, 0))
    for _ in range(600):  # large: up to and past the one-round limit
        pts.append(rng.choice([1, -1]) * 10 ** rng.uniform(1, 7))
    for _ in range(600):  # within a hair of k pi/2, where the reduction cancels
        k = rng.randint(-4000, 4000)
        pts.append(float(k * mp.pi / 2) * (1 + rng.uniform(-1e-9, 1e-9)))
    return pts


def sincos_fixture():
    rows = []
    for x in sincos_points():
        s, c = mp.sin(mp.mpf(x)), mp.cos(mp.mpf(x))
        rows.append([repr(v) for v in (x, float(s), float(s - mp.mpf(float(s))), float(c), float(c - mp.mpf(float(c))))])
    return {
        "doc": "sin x and cos x at 50 digits: [x, nearest double to sin, remainder, nearest double to cos, remainder] (verify/precision/reference.py)",
        "points": rows,
    }


def write_or_check(path, data, check):
    text = json.dumps(data, indent=1) + "\n"
    if "points" in data:  # one point per line
        rows = ",\n".join(json.dumps(r) for r in data["points"])
        text = f'{{"doc": {json.dumps(data["doc"])},\n"points": [\n{rows}\n]}}\n'
    if check:
        if path.read_text() != text:
            print(f"{path}: differs from what reference.py writes; rerun it")
            return 1
        print(f"{path.relative_to(HERE.parent.parent)}: up to date")
        return 0
    path.write_text(text)
    print(f"wrote {path}")
    return 0


def main(argv):
    data = {
        "doc": "diff_drive step_exact and step_exact_jac_p at omega*dt = s, 50-digit mpmath (verify/precision/reference.py)",
        "params": PARAMS,
        "cases": [case(s) for s in S_VALUES],
    }
    check = "--check" in argv
    failed = write_or_check(FIXTURE, data, check)
    failed |= write_or_check(ATAN2_FIXTURE, atan2_fixture(), check)
    return failed | write_or_check(SINCOS_FIXTURE, sincos_fixture(), check)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
