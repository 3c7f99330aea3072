#!/usr/bin/env python3
"""wrenfold's code for the peer benchmark (issues #13, #39): the kernels of
verify/casadi/reference.py's PEER_KERNELS, built from the same specs with
wrenfold's own symbolic library (its differentiation, its simplification, its
common-subexpression elimination) and emitted by its generators, never edited
by hand, in the three builds a wrenfold user has:

    verify/peers/wrenfold/kernels.rs       Rust, std's float methods
    verify/peers/wrenfold/kernels_libm.rs  Rust for no_std: the same code with
                                           libm's functions (wrenfold's documented
                                           way: a generator that formats calls)
    verify/peers/wrenfold/kernels.h        C++ (wrenfold's span headers, which
                                           its pip package installs)

    python3 verify/peers/wrenfold_kernels.py           # write the files
    python3 verify/peers/wrenfold_kernels.py --check   # fail if a committed file differs

Each kernel takes its arguments in CasADi's order (so the benchmark feeds every
side the same arrays) and writes every output through an output argument. The
exact step switches to a series where |omega dt| <= 0.05 with wrenfold's own
conditional (`sym.where`), as kinegen's kernels do.
"""
import sys
import tomllib
from pathlib import Path

from wrenfold import code_generation as cg
from wrenfold import sym, type_info

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "verify" / "casadi"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from peer_files import body_twist, write_or_check  # noqa: E402
from reference import PEER_KERNELS, STATE, chord_step, define, small_angle_factors, to_sx, users_form  # noqa: E402

OUT_DIR = Path(__file__).resolve().parent / "wrenfold"
# libm's names for the functions wrenfold calls (`abs` is `fabs` there, a
# power `pow`)
LIBM_NAMES = {"abs": "fabs", "powf": "pow", "powi": "pow"}

FUNCTIONS = {"sin": sym.sin, "cos": sym.cos, "tan": sym.tan, "atan": sym.atan, "atan2": sym.atan2,
             "sqrt": sym.sqrt, "exp": sym.exp, "ln": sym.log, "abs": sym.abs}


def kernels(spec, desc, arg_names, wanted, users=False):
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
    twist = body_twist(spec, env, FUNCTIONS)
    out = {"twist": twist}
    if "dt" in arg_names:
        x, y, th, dt = env["x"], env["y"], env["theta"], env["dt"]
        vx, vy, om = twist
        a = om * dt
        # wrenfold's own conditional: it emits an if/else and evaluates one side
        sinc, cosc = small_angle_factors(a, sym.sin, sym.cos, sym.abs, sym.where)
        s, c = sinc * dt, cosc * dt
        bx, by = s * vx - c * vy, c * vx + s * vy
        step = [x + sym.cos(th) * bx - sym.sin(th) * by, y + sym.sin(th) * bx + sym.cos(th) * by, th + a]
        if users:
            step = chord_step(x, y, th, dt, twist, sym.sin, sym.cos, sym.abs, sym.where)
        out["step_exact"] = step
        for g in ("x", "p"):
            out[f"step_exact_jac_{g}"] = sym.jacobian(step, [env[n] for n in groups[g]])
    obs_env = dict(env)
    obs_env.update({"vx": twist[0], "vy": twist[1], "omega": twist[2]})
    for o in spec.get("observation", []):
        if any(w.startswith(f"obs_{o['name']}") for w in wanted):
            h = [to_sx(e, obs_env, FUNCTIONS) for e in o["expr"]]
            out[f"obs_{o['name']}"] = h
            out[f"obs_{o['name']}_jac_x"] = sym.jacobian(h, [env[n] for n in STATE])
    return out


class LibmRustGenerator(cg.RustGenerator):
    """wrenfold's Rust generator with libm's functions instead of std's
    float methods, for a no_std build."""

    def format_call_std_function(self, element) -> str:
        name = str(element.function).split(".")[-1].lower()
        args = ", ".join(self.format(a) for a in element.args)
        return f"libm::{LIBM_NAMES.get(name, name)}({args})"


def descriptions():
    """wrenfold's description of every peer kernel, in PEER_KERNELS order."""
    import casadi  # noqa: F401  (reference.py's import; fails early if missing)
    from reference import model
    out = []
    for name, model_name, outs in PEER_KERNELS:
        spec = tomllib.loads((ROOT / "spec" / f"{model_name}.toml").read_text())
        _, funcs, _ = model(spec)
        arg_names = funcs[outs[0]][0]
        desc = cg.FunctionDescription(name)
        exprs = kernels(spec, desc, arg_names, outs, users_form(name))
        for o in outs:
            e = exprs[o]
            value = e if isinstance(e, sym.MatrixExpr) else sym.vector(*e)
            desc.add_output_argument(o, False, value)
        out.append(cg.transpile(desc))
    return out


def generate():
    """{file name: text} of the three builds."""
    import wrenfold
    made = f"Generated by verify/peers/wrenfold_kernels.py with wrenfold {wrenfold.__version__}: do not edit."
    rust_header = f"// {made}\n#![allow(clippy::all, non_snake_case, unused_parens, unused_variables)]\n\n"
    defs = descriptions()
    files = {}
    for file, generator in (("kernels.rs", cg.RustGenerator()), ("kernels_libm.rs", LibmRustGenerator())):
        files[file] = rust_header + "\n\n".join(generator.generate(d) for d in defs) + "\n"
    cpp = "\n\n".join(cg.CppGenerator().generate(d) for d in defs)
    files["kernels.h"] = (f"// {made}\n#pragma once\n#include <cmath>\n#include <cstdint>\n\n#include <wrenfold/span.h>\n\n"
                          f"namespace wrenfold_peer {{\n\n{cpp}\n\n}}  // namespace wrenfold_peer\n")
    return files


def main(argv):
    write_or_check(OUT_DIR, generate(), argv, "verify/peers/wrenfold_kernels.py")


if __name__ == "__main__":
    main(sys.argv[1:])
