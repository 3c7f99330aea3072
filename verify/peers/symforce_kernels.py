#!/usr/bin/env python3
"""SymForce's code for the peer benchmark (issue #39): the kernels of
verify/casadi/reference.py's PEER_KERNELS, built from the same specs with
SymForce's symbolic API (symengine underneath: its differentiation and its
common-subexpression elimination) and emitted by its code generators, never
edited by hand:

    verify/peers/symforce/kernels.h    C++ (Eigen types, as SymForce emits)

SymForce 0.12's Rust generator is not a peer here: its code for these kernels
does not compile (the series switch's comparison is declared `f64`), and where
it compiles it computes something else: sqrt(dx^2 + dy^2) of the landmark
range is printed `dx.powf(2) + dy2.powf(1/2)`, the sum's parentheses lost
(`--rust` writes that code to symforce/kernels_rust.txt to look at).

    python3 verify/peers/symforce_kernels.py           # write the files
    python3 verify/peers/symforce_kernels.py --check   # fail if a committed file differs

Arguments come in CasADi's order. The exact step switches to a series where
|omega dt| <= 0.05 through SymForce's own conditional (`sf.Piecewise`, a
ternary in the generated code), the same switch and order as kinegen's.
"""
import re
import sys
import tomllib
from pathlib import Path

import symforce

# epsilon 0 on purpose: the small-angle switch is an explicit Piecewise, so
# SymForce's warning about epsilon (one per kernel) says nothing here
symforce.set_epsilon_to_zero()
symforce.set_log_level("error")
import symforce.symbolic as sf  # noqa: E402
from symforce import codegen  # noqa: E402
from symforce.codegen.backends.rust.rust_config import RustConfig  # noqa: E402
from symforce.values import Values  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "verify" / "casadi"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from peer_files import body_twist, write_or_check  # noqa: E402
from reference import PEER_KERNELS, STATE, chord_step, define, small_angle_factors, to_sx, users_form  # noqa: E402

OUT_DIR = Path(__file__).resolve().parent / "symforce"
FUNCTIONS = {"sin": sf.sin, "cos": sf.cos, "tan": sf.tan, "atan": sf.atan, "atan2": sf.atan2,
             "sqrt": sf.sqrt, "exp": sf.exp, "ln": sf.log, "abs": sf.Abs}


def where(c, t, f):
    return sf.Piecewise((t, c), (f, True))


def kernel(name, spec, arg_names, wanted):
    """(inputs, outputs) Values of one peer kernel."""
    inputs = [i["name"] for i in spec.get("input", [])]
    noise = [n["name"] for n in spec.get("noise", [])]
    params = [p["name"] for p in spec.get("parameter", []) if not p.get("const", False)]
    groups = {"x": STATE, "u": inputs, "w": noise, "p": params, "lm": ["xl", "yl"]}
    args, env = Values(), {}
    for a in arg_names:
        if a == "dt":
            args["dt"] = env["dt"] = sf.Symbol("dt")
            continue
        v = sf.Matrix([sf.Symbol(f"{a}{k}") for k in range(len(groups[a]))])
        args[a] = v
        env.update({n: v[k] for k, n in enumerate(groups[a])})
    env.update({p["name"]: float(p["nominal"]) for p in spec.get("parameter", []) if p.get("const", False)})
    env.update({n: 0 for n in noise if n not in env})
    define(spec, env, FUNCTIONS)
    twist = body_twist(spec, env, FUNCTIONS)
    out = {"twist": sf.Matrix(twist)}
    if "dt" in arg_names:
        x, y, th, dt = env["x"], env["y"], env["theta"], env["dt"]
        vx, vy, om = twist
        a = om * dt
        sinc, cosc = small_angle_factors(a, sf.sin, sf.cos, sf.Abs, where)
        s, c = sinc * dt, cosc * dt
        bx, by = s * vx - c * vy, c * vx + s * vy
        step = sf.Matrix([x + sf.cos(th) * bx - sf.sin(th) * by, y + sf.sin(th) * bx + sf.cos(th) * by, th + a])
        if users_form(name):
            step = sf.Matrix(chord_step(x, y, th, dt, twist, sf.sin, sf.cos, sf.Abs, where))
        out["step_exact"] = step
        for g in ("x", "p"):
            out[f"step_exact_jac_{g}"] = step.jacobian(sf.Matrix([env[n] for n in groups[g]]))
    obs_env = dict(env)
    obs_env.update({"vx": twist[0], "vy": twist[1], "omega": twist[2]})
    for o in spec.get("observation", []):
        if any(w.startswith(f"obs_{o['name']}") for w in wanted):
            h = sf.Matrix([to_sx(e, obs_env, FUNCTIONS) for e in o["expr"]])
            out[f"obs_{o['name']}"] = h
            out[f"obs_{o['name']}_jac_x"] = h.jacobian(sf.Matrix([env[n] for n in STATE]))
    return args, Values(**{w: out[w] for w in wanted})


def generate():
    """{file name: text} of the C++ and Rust builds."""
    import casadi  # noqa: F401  (reference.py's import; fails early if missing)
    from reference import model
    import tempfile
    rust = "--rust" in sys.argv
    files = {"kernels.h": [], "kernels.rs": []}
    for name, model_name, outs in PEER_KERNELS:
        spec = tomllib.loads((ROOT / "spec" / f"{model_name}.toml").read_text())
        _, funcs, _ = model(spec)
        args, outputs = kernel(name, spec, funcs[outs[0]][0], outs)
        for file, config in (("kernels.h", codegen.CppConfig()), ("kernels.rs", RustConfig()))[: 1 + rust]:
            cg = codegen.Codegen(inputs=args, outputs=outputs, config=config, name=name)
            with tempfile.TemporaryDirectory() as tmp:
                made = cg.generate_function(output_dir=tmp, skip_directory_nesting=True)
                text = Path(made.generated_files[0]).read_text()
            files[file].append(strip_banner(text))
    made = f"Generated by verify/peers/symforce_kernels.py with SymForce {symforce.__version__}: do not edit."
    cpp = "\n".join(files["kernels.h"])
    rust_code = "\n".join(files["kernels.rs"])
    files = {"kernels.h": f"// {made}\n#pragma once\n\n{cpp}"}
    if rust:
        files["kernels_rust.txt"] = f"// {made}\n\npub mod sym {{\n{rust_code}}} // mod sym\n"
    return files


def strip_banner(text):
    """A generated file without its banner and, for C++, its #pragma once
    (one per combined file)."""
    text = re.sub(r"^// -+\n(//.*\n)*// -+\n", "", text)
    # one `mod sym` around every Rust function (a file may not repeat a module)
    text = text.replace("pub mod sym {\n", "").replace("} // mod sym\n", "")
    return text.replace("#pragma once\n", "")


def main(argv):
    write_or_check(OUT_DIR, generate(), argv, "verify/peers/symforce_kernels.py")


if __name__ == "__main__":
    main(sys.argv[1:])
