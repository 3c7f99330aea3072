"""The guide's Python page runs as written (docs/src/howto/python.md).

The page's ```python blocks run in order in one namespace, from a temporary
folder where `spec/` and `data/` are the repository's (the page's paths are
the repository root's); the markup is tests/howtos.rs's:
- a hidden `<!-- test: ... -->` comment runs its shell there (with the
  kinegen command line on the PATH): it makes what the page takes as given;
- `<!-- test: not run: WHY -->` right before a block leaves it out;
- a ```text block right after a Python block shows lines it prints, in
  order (`...` skips lines).
"""
import contextlib
import io
import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "src" / "howto" / "python.md"
# resolved now: the test changes directory (scripts/test.sh gives a relative path)
BIN = Path(os.environ.get("KINEGEN_BIN", ROOT / os.environ.get("CARGO_TARGET_DIR", "target") / "debug" / "kinegen")).resolve()


def steps(text):
    """(kind, body, line) in page order: kind is "shell", "python" or "shows"."""
    out, skip = [], False
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        if line.startswith("<!-- test:"):
            body = [line[len("<!-- test:"):]]
            while not body[-1].rstrip().endswith("-->"):
                i += 1
                body.append(lines[i])
            body = "\n".join(body).rstrip()[:-3].strip()
            if body.startswith("not run:"):
                assert body[len("not run:"):].strip(), f"python.md:{i + 1}: say why it is not run"
                skip = True
            else:
                out.append(("shell", body, i + 1))
            i += 1
            continue
        m = re.match(r"```(\w*)$", line)
        if m:
            start = i + 1
            j = start
            while not lines[j].strip().startswith("```"):
                j += 1
            body = "\n".join(lines[start:j]) + "\n"
            kind = m.group(1)
            if skip:
                skip = False
            elif kind == "python":
                out.append(("python", body, start + 1))
            elif kind == "text" and out and out[-1][0] == "python":
                out.append(("shows", body, start + 1))
            i = j + 1
            continue
        i += 1
    return out


def shows(shown, printed):
    """Each shown line is printed, in order (`...` skips lines)."""
    got = [l.rstrip() for l in printed.splitlines()]
    at = 0
    for want in (l.rstrip() for l in shown.splitlines()):
        if want == "...":
            continue
        assert want in got[at:], f"`{want}` is not printed (after line {at}):\n{printed}"
        at += got[at:].index(want) + 1


def test_the_python_page_runs_as_written(tmp_path, monkeypatch):
    for d in ("spec", "data"):
        (tmp_path / d).symlink_to(ROOT / d)
    monkeypatch.chdir(tmp_path)
    env = dict(os.environ, PATH=f"{BIN.parent}{os.pathsep}{os.environ.get('PATH', '')}")
    namespace, printed, ran = {}, "", 0
    for kind, body, line in steps(PAGE.read_text()):
        if kind == "shell":
            p = subprocess.run(["bash", "-euo", "pipefail", "-c", body], env=env, capture_output=True, text=True)
            assert p.returncode == 0, f"python.md:{line}: {body}\n{p.stdout}\n{p.stderr}"
        elif kind == "python":
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                try:
                    exec(compile(body, f"python.md:{line}", "exec"), namespace)
                except Exception as e:
                    pytest.fail(f"python.md:{line}: {type(e).__name__}: {e}")
            printed, ran = out.getvalue(), ran + 1
        else:
            shows(body, printed)
    assert ran >= 5, f"only {ran} Python blocks ran"


def test_the_page_reader_is_not_blind():
    page = ("<!-- test: echo hi > a.txt -->\n```python\nprint(1)\n```\n```text\n1\n```\n"
            "<!-- test: not run: no -->\n```python\nraise SystemExit\n```\n")
    assert steps(page) == [("shell", "echo hi > a.txt", 1), ("python", "print(1)\n", 3), ("shows", "1\n", 6)]
    shows("1\n...\n3", "1\n2\n3")
    with pytest.raises(AssertionError):
        shows("3\n1", "1\n2\n3")
