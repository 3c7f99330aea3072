"""What the peer generators (wrenfold_kernels.py, symforce_kernels.py) share:
the symbolic 3x3 inverse of seed 000's normal equations, and writing their
files or checking that the committed ones are what they would write."""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def inverse3(m):
    """Inverse of a symbolic 3x3 matrix (list of rows) by its adjugate."""
    c = [[m[(j + 1) % 3][(i + 1) % 3] * m[(j + 2) % 3][(i + 2) % 3]
          - m[(j + 1) % 3][(i + 2) % 3] * m[(j + 2) % 3][(i + 1) % 3] for j in range(3)] for i in range(3)]
    det = sum(m[0][k] * c[k][0] for k in range(3))
    return [[c[i][j] / det for j in range(3)] for i in range(3)]


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
