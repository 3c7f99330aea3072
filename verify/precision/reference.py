#!/usr/bin/env python3
"""High-precision reference for the exact step near its removable singularity.

diff_drive's `step_exact` and `step_exact_jac_p` (seed 003's exact integration
on SE(2)), evaluated with mpmath at 50 digits for omega*dt = s from 0 through
the series switch (0.05) to 1, written with the analytic forms
sin(s)/s = sinc(s) and (1 - cos s)/s = s/2 sinc(s/2)^2, which have no
cancellation at any s. `verify/tests/precision.rs` checks the generated
kernels against it (relative to each output row's scale).

    python3 verify/precision/reference.py           # (re)write near_zero.json
    python3 verify/precision/reference.py --check   # fail if it differs
"""
import json
import sys
from pathlib import Path

import mpmath as mp

mp.mp.dps = 50
HERE = Path(__file__).resolve().parent
FIXTURE = HERE / "near_zero.json"
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


def main(argv):
    data = {
        "doc": "diff_drive step_exact and step_exact_jac_p at omega*dt = s, 50-digit mpmath (verify/precision/reference.py)",
        "params": PARAMS,
        "cases": [case(s) for s in S_VALUES],
    }
    text = json.dumps(data, indent=1) + "\n"
    if "--check" in argv:
        if FIXTURE.read_text() != text:
            print(f"{FIXTURE}: differs from what reference.py writes; rerun it")
            return 1
        print(f"{FIXTURE.relative_to(HERE.parent.parent)}: up to date")
        return 0
    FIXTURE.write_text(text)
    print(f"wrote {FIXTURE}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
