"""What the peer generators (wrenfold_kernels.py, symforce_kernels.py) share:
the body twist of a spec in a peer's symbolic library, and writing their files
or checking that the committed ones are what they would write."""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "verify" / "casadi"))
from reference import to_sx  # noqa: E402


def inverse3(m):
    """Inverse of a symbolic 3x3 matrix (list of rows) by its adjugate."""
    c = [[m[(j + 1) % 3][(i + 1) % 3] * m[(j + 2) % 3][(i + 2) % 3]
          - m[(j + 1) % 3][(i + 2) % 3] * m[(j + 2) % 3][(i + 1) % 3] for j in range(3)] for i in range(3)]
    det = sum(m[0][k] * c[k][0] for k in range(3))
    return [[c[i][j] / det for j in range(3)] for i in range(3)]


def body_twist(spec, env, functions):
    """The spec's body twist [vx, vy, omega] in the library of `functions`
    (`env` holds its symbols): the [motion] rows, or for [constraints] the
    least-squares twist through the normal equations (seed 000 eq. 9-10)."""
    if "constraints" not in spec:
        return [to_sx(spec["motion"][k], env, functions) for k in ("vx", "vy", "omega")]
    c = spec["constraints"]
    s = [[to_sx(e, env, functions) for e in row["coeffs"]] for row in c["row"]]
    q = [env[row["rate"]] for row in c["row"]]
    sts = [[sum(r[i] * r[j] for r in s) for j in range(3)] for i in range(3)]
    stq = [sum(r[i] * qk for r, qk in zip(s, q)) for i in range(3)]
    inv = inverse3(sts)
    twist = [sum(inv[k][j] * stq[j] for j in range(3)) for k in range(3)]
    if "noise" in c:
        twist = [t + env.get(n, 0) for t, n in zip(twist, c["noise"])]
    return twist


def write_or_check(out_dir, files, argv, script):
    """Write {file name: text} under out_dir, or with --check in argv exit
    non-zero naming the committed files that differ."""
    check = "--check" in argv
    stale = []
    for file, text in files.items():
        path = out_dir / file
        if check:
            if not path.exists() or path.read_text() != text:
                stale.append(str(path.relative_to(ROOT)))
            continue
        out_dir.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        print(f"wrote {path.relative_to(ROOT)}")
    if stale:
        sys.exit(f"stale: {', '.join(stale)}: run python3 {script}")
    if check:
        print(f"{out_dir.relative_to(ROOT)}: up to date")
