#!/usr/bin/env python3
"""wrenfold's Rust code for the peer benchmark (issue #13): the kernels of
verify/casadi/reference.py's PEER_KERNELS, built from the same specs with
wrenfold's own symbolic library (its differentiation, its simplification, its
common-subexpression elimination) and emitted by its Rust generator into
verify/peers/wrenfold/kernels.rs, never edited by hand.

    python3 verify/peers/wrenfold_kernels.py           # write the file
    python3 verify/peers/wrenfold_kernels.py --check   # fail if the committed file differs

Each kernel takes its arguments in CasADi's order (so the benchmark feeds both
the same arrays) and writes every output through an output argument. The exact
step is the plain closed form, as in the CasADi peer: the benchmark compares
outputs only where |omega dt| > 0.05.
"""
import sys
import tomllib
from pathlib import Path

from wrenfold import code_generation as cg
from wrenfold import sym, type_info

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "verify" / "casadi"))
from reference import PEER_KERNELS, STATE, define, to_sx  # noqa: E402

OUT = Path(__file__).resolve().parent / "wrenfold" / "kernels.rs"

FUNCTIONS = {"sin": sym.sin, "cos": sym.cos, "tan": sym.tan, "atan": sym.atan, "atan2": sym.atan2,
             "sqrt": sym.sqrt, "exp": sym.exp, "ln": sym.log, "abs": sym.abs}


def inverse3(m):
    """Inverse of a symbolic 3x3 matrix (list of rows) by its adjugate."""
    c = [[m[(j + 1) % 3][(i + 1) % 3] * m[(j + 2) % 3][(i + 2) % 3]
          - m[(j + 1) % 3][(i + 2) % 3] * m[(j + 2) % 3][(i + 1) % 3] for j in range(3)] for i in range(3)]
    det = sum(m[0][k] * c[k][0] for k in range(3))
    return [[c[i][j] / det for j in range(3)] for i in range(3)]


def kernels(spec, desc, arg_names, wanted):
    """Add the spec's arguments to `desc` (in `arg_names` order) and return
    the `wanted` outputs (and maybe more) as wrenfold expressions."""
    inputs = [i["name"] for i in spec.get("input", [])]
    noise = [n["name"] for n in spec.get("noise", [])]
    params = [p["name"] for p in spec.get("parameter", []) if not p.get("const", False)]
    groups = {"x": STATE, "u": inputs, "w": noise, "p": params, "lm": ["xl", "yl"]}
    env = {}
    for a in arg_names:
        if a == "dt":
            env["dt"] = desc.add_input_argument("dt", type_info.ScalarType(type_info.NumericType.Float))
            continue
        v = desc.add_input_argument(a, type_info.MatrixType(len(groups[a]), 1))
        env.update({n: v[k] for k, n in enumerate(groups[a])})
    env.update({p["name"]: float(p["nominal"]) for p in spec.get("parameter", []) if p.get("const", False)})
    # a kernel without the noise argument is the noise-free model
    env.update({n: 0 for n in noise if n not in env})
    define(spec, env, FUNCTIONS)
    if "constraints" in spec:
        # seed 000 eq. 9-10: the least-squares twist through the normal equations
        c = spec["constraints"]
        s = [[to_sx(e, env, FUNCTIONS) for e in row["coeffs"]] for row in c["row"]]
        q = [env[row["rate"]] for row in c["row"]]
        sts = [[sum(r[i] * r[j] for r in s) for j in range(3)] for i in range(3)]
        stq = [sum(r[i] * qk for r, qk in zip(s, q)) for i in range(3)]
        inv = inverse3(sts)
        twist = [sum(inv[k][j] * stq[j] for j in range(3)) for k in range(3)]
        if "noise" in c:
            twist = [t + env.get(n, 0) for t, n in zip(twist, c["noise"])]
    else:
        twist = [to_sx(spec["motion"][k], env, FUNCTIONS) for k in ("vx", "vy", "omega")]
    out = {"twist": twist}
    if "dt" in arg_names:
        x, y, th, dt = env["x"], env["y"], env["theta"], env["dt"]
        vx, vy, om = twist
        a = om * dt
        s, c = sym.sin(a) / om, (1 - sym.cos(a)) / om
        bx, by = s * vx - c * vy, c * vx + s * vy
        step = [x + sym.cos(th) * bx - sym.sin(th) * by, y + sym.sin(th) * bx + sym.cos(th) * by, th + a]
        out["step_exact"] = step
        for g in ("x", "p"):
            out[f"step_exact_jac_{g}"] = sym.jacobian(step, [env[n] for n in groups[g]])
    obs_env = dict(env)
    obs_env.update({"vx": twist[0], "vy": twist[1], "omega": twist[2]})
    for o in spec.get("observation", []):
        if f"obs_{o['name']}" in wanted:
            h = [to_sx(e, obs_env, FUNCTIONS) for e in o["expr"]]
            out[f"obs_{o['name']}"] = h
            out[f"obs_{o['name']}_jac_x"] = sym.jacobian(h, [env[n] for n in STATE])
    return out


def generate():
    """The Rust source of every peer kernel, in PEER_KERNELS order."""
    import casadi  # noqa: F401  (reference.py's import; fails early if missing)
    sys.path.insert(0, str(ROOT / "verify" / "casadi"))
    from reference import model
    code = []
    for name, model_name, outs in PEER_KERNELS:
        spec = tomllib.loads((ROOT / "spec" / f"{model_name}.toml").read_text())
        _, funcs, _ = model(spec)
        arg_names = funcs[outs[0]][0]
        desc = cg.FunctionDescription(name)
        exprs = kernels(spec, desc, arg_names, outs)
        for o in outs:
            e = exprs[o]
            value = e if isinstance(e, sym.MatrixExpr) else sym.vector(*e)
            desc.add_output_argument(o, False, value)
        code.append(cg.RustGenerator().generate(cg.transpile(desc)))
    import wrenfold
    header = (f"// Generated by verify/peers/wrenfold_kernels.py with wrenfold {wrenfold.__version__}: "
              "do not edit.\n#![allow(clippy::all, non_snake_case, unused_parens, unused_variables)]\n\n")
    return header + "\n\n".join(code) + "\n"


def main(argv):
    text = generate()
    if "--check" in argv:
        if OUT.read_text() != text:
            sys.exit(f"{OUT} is stale: run python3 verify/peers/wrenfold_kernels.py")
        print(f"{OUT.relative_to(ROOT)}: up to date")
        return
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT.relative_to(ROOT)}")


if __name__ == "__main__":
    main(sys.argv[1:])
