#!/usr/bin/env python3
"""Independent CasADi references for kinegen's generated kernels.

Reads each spec under spec/ itself (tomllib), turns its math strings into CasADi
SX expressions with Python's ast (never looking at kinegen's output), builds the
Euler and exact SE(2) steps, the observations and their Jacobians with CasADi's
own algorithmic differentiation, evaluates them at seeded sample points and
writes verify/casadi/fixtures/<model>.json. The Rust test verify/tests/casadi.rs
compares the compiled kernels with these fixtures.

    python3 verify/casadi/reference.py            # write the fixtures
    python3 verify/casadi/reference.py --check    # regenerate in memory, compare with the committed ones
    python3 verify/casadi/reference.py --spec my.toml --out DIR   # one spec (kinegen verify uses this)
    python3 verify/casadi/reference.py --emit-c verify/peers/casadi   # C code of the peer benchmark
    python3 verify/casadi/reference.py --check-c   # fail if that committed C code is stale
"""
import ast
import json
import math
import sys
import tomllib
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
OUT = Path(__file__).resolve().parent / "fixtures"
STATE = ["x", "y", "theta"]
SAMPLES = 40


CASADI_FUNCTIONS = {"sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "atan": ca.atan, "atan2": ca.atan2,
                    "sqrt": ca.sqrt, "exp": ca.exp, "ln": ca.log, "abs": ca.fabs,
                    "sign": ca.sign}


def to_sx(src, env, functions=None):
    """A spec math string as a CasADi SX expression (`^` is power); with
    `functions`, as an expression of another symbolic library."""
    functions = functions or CASADI_FUNCTIONS
    tree = ast.parse(src.replace("^", "**"), mode="eval")

    def go(n):
        if isinstance(n, ast.Expression):
            return go(n.body)
        if isinstance(n, ast.Constant):
            return float(n.value)
        if isinstance(n, ast.Name):
            if n.id == "pi":
                return math.pi
            return env[n.id]
        if isinstance(n, ast.UnaryOp):
            v = go(n.operand)
            return -v if isinstance(n.op, ast.USub) else v
        if isinstance(n, ast.BinOp):
            a, b = go(n.left), go(n.right)
            # an integer exponent stays an integer, as a user of a symbolic
            # library writes `x**2` (wrenfold makes a float power a pow call)
            if isinstance(n.op, ast.Pow) and isinstance(n.right, ast.Constant) and float(n.right.value).is_integer():
                b = int(n.right.value)
            return {ast.Add: lambda: a + b, ast.Sub: lambda: a - b, ast.Mult: lambda: a * b,
                    ast.Div: lambda: a / b, ast.Pow: lambda: a ** b}[type(n.op)]()
        if isinstance(n, ast.Call):
            args = [go(a) for a in n.args]
            return functions[n.func.id](*args)
        raise ValueError(f"unsupported syntax in `{src}`")

    return go(tree)


def define(spec, env, functions=None):
    """Add the spec's definitions to `env`, in dependency order."""
    pending = {d["name"]: d["expr"] for d in spec.get("define", [])}
    while pending:
        progress = False
        for name, src in list(pending.items()):
            try:
                env[name] = to_sx(src, env, functions)
                del pending[name]
                progress = True
            except KeyError:
                pass
        if not progress:
            raise ValueError(f"unresolvable definitions {list(pending)}")


def small_angle_factors(a, sin, cos, fabs, where):
    """(sin(a)/a, (1 - cos a)/a) with the small-angle handling a peer's user
    would write: the closed form where |a| > 0.05, else its series to a^8 and
    a^9 (the same switch and order as kinegen's kernels, so that both are
    equally accurate). `where(c, x, y)` is the peer's own conditional."""
    a2 = a * a
    sinc = 1 - a2 / 6 * (1 - a2 / 20 * (1 - a2 / 42 * (1 - a2 / 72)))
    cosc = a / 2 * (1 - a2 / 12 * (1 - a2 / 30 * (1 - a2 / 56 * (1 - a2 / 90))))
    big = fabs(a) > 0.05
    return where(big, sin(a) / a, sinc), where(big, (1 - cos(a)) / a, cosc)


# The guard a user of a peer writes by hand around the chord form's division
# by the turn rate (rad/s): the straight line below it.
USERS_GUARD = 1e-6


def chord_step(x, y, th, dt, twist, sin, cos, fabs, where):
    """The exact step as a robotics user writes it in a peer's library
    (issue 66): the chord form of motion at a constant twist, x + (vx
    (sin(th + a) - sin th) + vy (cos(th + a) - cos th))/omega..., and the
    straight line where |omega| is under USERS_GUARD, through the peer's own
    conditional `where`. Cheaper than a series switch, and less accurate
    near omega dt = 0, where the differences of sines cancel."""
    vx, vy, om = twist
    a = om * dt
    s0, c0, s1, c1 = sin(th), cos(th), sin(th + a), cos(th + a)
    ds, dc = s1 - s0, c1 - c0
    turning = fabs(om) > USERS_GUARD
    dx = where(turning, (vx * ds + vy * dc) / om, (vx * c0 - vy * s0) * dt)
    dy = where(turning, (vy * ds - vx * dc) / om, (vx * s0 + vy * c0) * dt)
    return [x + dx, y + dy, th + a]


def model(spec, guard=False, users=False):
    """The spec's kernels as CasADi expressions. With `guard` the exact step
    switches to a series near omega dt = 0 (`small_angle_factors`), as the
    peer benchmark's accuracy-matched kernels do; with `users` it is the
    chord form a user writes (`chord_step`); with neither, the plain closed
    form."""
    inputs = [i["name"] for i in spec.get("input", [])]
    noise = [n["name"] for n in spec.get("noise", [])]
    params = [p for p in spec.get("parameter", []) if not p.get("const", False)]
    consts = {p["name"]: float(p["nominal"]) for p in spec.get("parameter", []) if p.get("const", False)}
    sym = {n: ca.SX.sym(n) for n in STATE + inputs + noise + [p["name"] for p in params] + ["dt", "xl", "yl"]}
    env = dict(sym)
    env.update(consts)
    define(spec, env)
    omega_meas = ca.SX.sym("omega_meas")
    if "constraints" in spec:
        # seed 000 eq. 9-10: the twist solves S z = q' in the least-squares sense;
        # here with CasADi's own linear solve of the normal equations (kinegen uses
        # an eigen-decomposition pseudo-inverse: two independent routes)
        c = spec["constraints"]
        S = ca.vertcat(*[ca.horzcat(*[to_sx(e, env) for e in row["coeffs"]]) for row in c["row"]])
        qd = ca.vertcat(*[sym[row["rate"]] for row in c["row"]])
        z = ca.solve(ca.mtimes(S.T, S), ca.mtimes(S.T, qd))
        twist_noisy = [z[k] + (sym[c["noise"][k]] if "noise" in c else 0) for k in range(3)]
        # gyrodometry, eq. 17: translation by least squares with the yaw rate imposed
        Sxi = S[:, 0:2]
        xi = ca.solve(ca.mtimes(Sxi.T, Sxi), ca.mtimes(Sxi.T, qd - S[:, 2] * omega_meas))
        gyro_twist = ca.vertcat(xi[0], xi[1])
    else:
        m = spec["motion"]
        twist_noisy = [to_sx(m[k], env) for k in ("vx", "vy", "omega")]
    zero_w = {sym[n]: 0 for n in noise}
    twist = [ca.substitute(t, ca.vertcat(*[sym[n] for n in noise]), ca.DM.zeros(len(noise))) if noise else t for t in twist_noisy]
    if "constraints" not in spec:
        gyro_twist = ca.vertcat(twist[0], twist[1])
    x, y, th, dt = sym["x"], sym["y"], sym["theta"], sym["dt"]
    vx, vy, om = twist_noisy
    euler = ca.vertcat(x + (ca.cos(th) * vx - ca.sin(th) * vy) * dt,
                       y + (ca.sin(th) * vx + ca.cos(th) * vy) * dt,
                       th + om * dt)
    # exact constant-twist motion on SE(2), written from the closed form
    a = om * dt
    s, c = ca.sin(a) / om, (1 - ca.cos(a)) / om
    if guard:
        sinc, cosc = small_angle_factors(a, ca.sin, ca.cos, ca.fabs, ca.if_else)
        s, c = sinc * dt, cosc * dt
    bx, by = s * vx - c * vy, c * vx + s * vy
    exact = ca.vertcat(x + ca.cos(th) * bx - ca.sin(th) * by, y + ca.sin(th) * bx + ca.cos(th) * by, th + a)
    if users:
        exact = ca.vertcat(*chord_step(x, y, th, dt, twist_noisy, ca.sin, ca.cos, ca.fabs, ca.if_else))
    groups = {"x": [sym[n] for n in STATE], "u": [sym[n] for n in inputs], "w": [sym[n] for n in noise],
              "p": [sym[p["name"]] for p in params], "dt": [dt], "lm": [sym["xl"], sym["yl"]], "omega": [omega_meas]}
    funcs = {}
    step_args = ["x", "u"] + (["w"] if noise else []) + ["p", "dt"]
    for form, f in (("euler", euler), ("exact", exact)):
        funcs[f"step_{form}"] = (step_args, f)
        for g in ("x", "u", "w", "p"):
            if groups[g]:
                funcs[f"step_{form}_jac_{g}"] = (step_args, ca.jacobian(f, ca.vertcat(*groups[g])))
    funcs["twist"] = (["u", "p"], ca.vertcat(*twist))
    funcs["twist_gyro"] = (["u", "omega", "p"], gyro_twist)
    obs_env = dict(env)
    obs_env.update({"vx": twist[0], "vy": twist[1], "omega": twist[2]})
    for o in spec.get("observation", []):
        h = ca.vertcat(*[to_sx(e, obs_env) for e in o["expr"]])
        args = ["x", "u", "p"] + (["lm"] if o.get("landmark", False) else [])
        funcs[f"obs_{o['name']}"] = (args, h)
        for g in ("x", "p"):
            if groups[g]:
                funcs[f"obs_{o['name']}_jac_{g}"] = (args, ca.jacobian(h, ca.vertcat(*groups[g])))
    return groups, funcs, params


def sample(spec, groups, params, rng, scale=1.0):
    """Sample points; rates scaled by input unit, |omega*dt| >= 0.05: the closed
    form above loses accuracy to cancellation as omega*dt -> 0 (relative error
    ~1e-16/(omega*dt)^2 in the Jacobians), which is exactly why kinegen switches
    to a series there; that branch is checked by the Rust property tests (finite
    differences, singular limits) instead."""
    vals = {}
    vals["x"] = [rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-3, 3)]
    ranges = {"count/s": 4000.0, "rad/s": 8.0, "rad": 0.6, "m/s": 1.0}
    # an input in a unit not listed here (a steering encoder in ticks) may need
    # wider values to turn the robot at all: `scale` > 1 (see `fixtures`)
    # samples declared ranges, and widens the others
    vals["u"] = [rng.uniform(*i["range"]) if scale > 1 and "range" in i
                 else rng.uniform(-1, 1) * ranges.get(i.get("unit", ""), 1.0) * scale
                 for i in spec.get("input", [])]
    vals["w"] = [rng.uniform(-0.03, 0.03) for _ in groups["w"]]
    vals["p"] = [float(p["nominal"]) * rng.uniform(0.9, 1.1) if p["nominal"] != 0 else rng.uniform(-0.05, 0.05) for p in params]
    vals["dt"] = [rng.uniform(0.01, 0.1)]
    vals["omega"] = [rng.uniform(-1.0, 1.0)]
    r, b = rng.uniform(1, 8), rng.uniform(-3, 3)
    vals["lm"] = [vals["x"][0] + r * math.cos(b), vals["x"][1] + r * math.sin(b)]
    return vals


def fixtures(spec_path):
    spec = tomllib.loads(spec_path.read_text())
    groups, funcs, params = model(spec)
    rng = np.random.default_rng(20261122)
    twist_fn = ca.Function("tw", [ca.vertcat(*groups["u"]), ca.vertcat(*groups["p"])], [funcs["twist"][1]])
    points = []
    for _ in range(SAMPLES):
        for attempt in range(2000):
            v = sample(spec, groups, params, rng, 10.0 ** (attempt // 200))
            om = float(twist_fn(v["u"], v["p"])[2])
            if abs(om * v["dt"][0]) > 0.05:
                break
        else:
            sys.exit(f"{spec_path}: no sampled input turns the robot by more than 0.05 rad "
                     "in a step (the closed-form reference needs |omega dt| > 0.05)")
        for name, (args, expr) in funcs.items():
            inputs = [ca.vertcat(*groups[a]) for a in args]
            f = ca.Function(name, inputs, [expr])
            out = np.array(f(*[v[a] for a in args])).reshape(expr.shape, order="F")
            points.append({"function": name, "args": {a: v[a] for a in args}, "out": out.flatten(order="C").tolist()})
    return {"model": spec["name"], "casadi": ca.__version__, "points": points}


# The kernels of the peer benchmark (verify/peers): first each row's outputs
# in one function, as a caller who needs them together would generate them
# (one CasADi Function, all outputs sharing its expression graph); then each
# kernel alone, as firmware that needs only it calls it.
PEER_KERNELS = [
    ("dd_step", "diff_drive", ["step_exact", "step_exact_jac_x", "step_exact_jac_p"]),
    ("uc_landmark", "unicycle_ekf", ["obs_landmark", "obs_landmark_jac_x"]),
    ("oc_twist", "omni_caster", ["twist"]),
    ("oc_step", "omni_caster", ["step_exact", "step_exact_jac_p"]),
    ("dd_step_exact", "diff_drive", ["step_exact"]),
    ("dd_step_exact_jac_x", "diff_drive", ["step_exact_jac_x"]),
    ("dd_step_exact_jac_p", "diff_drive", ["step_exact_jac_p"]),
    ("uc_obs_landmark", "unicycle_ekf", ["obs_landmark"]),
    ("uc_obs_landmark_jac_x", "unicycle_ekf", ["obs_landmark_jac_x"]),
    ("oc_step_exact", "omni_caster", ["step_exact"]),
    ("oc_step_exact_jac_p", "omni_caster", ["step_exact_jac_p"]),
    # the steps again as the peers' users write them (`chord_step`): the
    # rows above are the accuracy-matched variants
    ("dd_step_users", "diff_drive", ["step_exact", "step_exact_jac_x", "step_exact_jac_p"]),
    ("oc_step_users", "omni_caster", ["step_exact", "step_exact_jac_p"]),
    ("dd_step_exact_users", "diff_drive", ["step_exact"]),
    ("dd_step_exact_jac_x_users", "diff_drive", ["step_exact_jac_x"]),
    ("dd_step_exact_jac_p_users", "diff_drive", ["step_exact_jac_p"]),
    ("oc_step_exact_users", "omni_caster", ["step_exact"]),
    ("oc_step_exact_jac_p_users", "omni_caster", ["step_exact_jac_p"]),
]


def users_form(name):
    """Whether a PEER_KERNELS entry is the users' form of its step."""
    return name.endswith("_users")


def emit_c(out_dir):
    """CasADi's C code for the peer benchmark (verify/peers): one file, written
    by CasADi's own code generator from the same specs, never edited by hand."""
    cg = ca.CodeGenerator("casadi_kernels.c", {"with_header": True, "casadi_real": "double", "casadi_int": "long long"})
    models = {}
    for name, model_name, outs in PEER_KERNELS:
        key = (model_name, users_form(name))
        if key not in models:
            spec = tomllib.loads((ROOT / "spec" / f"{model_name}.toml").read_text())
            models[key] = model(spec, guard=True, users=key[1])
        groups, funcs, _ = models[key]
        args = funcs[outs[0]][0]
        cg.add(ca.Function(name, [ca.vertcat(*groups[a]) for a in args], [funcs[o][1] for o in outs]))
    out_dir.mkdir(parents=True, exist_ok=True)
    cg.generate(str(out_dir) + "/")
    print(f"wrote {out_dir}/casadi_kernels.c and .h (CasADi {ca.__version__})")


def check_c():
    """Fail if the committed peer C code differs from what emit_c writes now."""
    import tempfile
    committed = ROOT / "verify" / "peers" / "casadi"
    with tempfile.TemporaryDirectory() as tmp:
        emit_c(Path(tmp))
        stale = [f for f in ("casadi_kernels.c", "casadi_kernels.h")
                 if (Path(tmp) / f).read_text() != (committed / f).read_text()]
    if stale:
        sys.exit(f"{committed}: {', '.join(stale)} stale: run python3 verify/casadi/reference.py --emit-c verify/peers/casadi")
    print(f"{committed.relative_to(ROOT)}: up to date")


def main():
    argv = sys.argv[1:]
    if "--emit-c" in argv:
        emit_c(Path(argv[argv.index("--emit-c") + 1]))
        return
    if "--check-c" in argv:
        check_c()
        return
    check = "--check" in argv
    out_dir = Path(argv[argv.index("--out") + 1]) if "--out" in argv else OUT
    specs = [Path(argv[argv.index("--spec") + 1])] if "--spec" in argv else sorted((ROOT / "spec").glob("*.toml"))
    bad = 0
    for spec_path in specs:
        doc = fixtures(spec_path)
        target = out_dir / f"{doc['model']}.json"
        if check:
            old = json.loads(target.read_text())
            worst = 0.0
            for a, b in zip(old["points"], doc["points"]):
                assert a["function"] == b["function"], "fixture layout changed"
                for p, q in zip(a["out"], b["out"]):
                    worst = max(worst, abs(p - q) / max(abs(p), abs(q), 1e-300) if p != q else 0.0)
            status = "ok" if worst < 1e-12 and len(old["points"]) == len(doc["points"]) else "DIFFERS"
            bad += status != "ok"
            print(f"{doc['model']}: {len(doc['points'])} reference values regenerated, worst relative difference to the committed fixtures {worst:.1e}: {status}")
        else:
            out_dir.mkdir(parents=True, exist_ok=True)
            target.write_text(json.dumps(doc, indent=0) + "\n")
            print(f"wrote {target} ({len(doc['points'])} reference values)")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
