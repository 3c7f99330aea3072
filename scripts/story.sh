#!/usr/bin/env bash
# The main job on bundled data: compare a model with a log, find the missing
# physical effect, add it to the spec, watch the error fall, regenerate kernels.
# Everything lands in report/ (HTML reports, the new spec, its kernels).
set -euo pipefail
cd "$(dirname "$0")/.."
out=report
mkdir -p "$out"
data=data/mystery_robot.csv
say() { printf '\n\033[1m$ %s\033[0m\n' "$*"; }

# The answer first: the analysis differentiates a spec by itself (automatic
# differentiation, no symbolica), so a binary without the symbolic stage
# (minutes less to build on a fresh clone) compares, diagnoses, adds the
# effect and calibrates. Only generate and verify, whose product is the
# symbolically simplified kernels, need the full binary, built afterwards.
# cargo shows its progress (a bar on a terminal, a line per crate otherwise)
echo "building kinegen without its symbolic stage (the analysis; about 7 min on a fresh clone, 2 cores) ..."
cargo build --no-default-features --bin kinegen
mkdir -p target/story && cp target/debug/kinegen target/story/kinegen-analysis
k=target/story/kinegen-analysis
say kinegen compare --spec spec/diff_drive.toml --data $data --report $out/compare
$k compare --spec spec/diff_drive.toml --data $data --report $out/compare

say kinegen diagnose --spec spec/diff_drive.toml --data $data --report $out/diagnose --json $out/diagnose.json
$k diagnose --spec spec/diff_drive.toml --data $data --report $out/diagnose --json $out/diagnose.json

# the winning effect, as the diagnosis named it (null if none)
effect=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["verdict"]["effect"] or "")' $out/diagnose.json 2>/dev/null || echo "")
if [ -z "$effect" ] || [ "$effect" = "null" ]; then
  echo "no missing effect found; nothing to add"; exit 0
fi
mkdir -p $out/spec
say kinegen add-effect --spec spec/diff_drive.toml --effect "$effect" --out $out/spec/diff_drive.toml
$k add-effect --spec spec/diff_drive.toml --effect "$effect" --out $out/spec/diff_drive.toml

say kinegen fit --spec spec/diff_drive.toml --data $data --report $out/fit-before
$k fit --spec spec/diff_drive.toml --data $data --report $out/fit-before
say kinegen fit --spec $out/spec/diff_drive.toml --data $data --report $out/fit-after
$k fit --spec $out/spec/diff_drive.toml --data $data --report $out/fit-after

# the README's picture: the position error before (nominal) and after (the
# effect added, calibrated), as the last report draws it
python3 - "$out/fit-after/index.html" "$out/story.svg" <<'PY'
import re, sys
html = open(sys.argv[1]).read()
svg = next(s for s in re.findall(r"<svg.*?</svg>", html, re.S) if "position error" in s)
open(sys.argv[2], "w").write(svg)
PY
echo "the README's picture, redrawn: $out/story.svg (docs/src/img/story.svg)"

# The kernels to embed: simplified and shared by the symbolic stage.
echo
echo "building kinegen with its symbolic stage (symbolica: 5-12 min on a fresh clone) ..."
cargo build --bin kinegen
k=target/debug/kinegen

say kinegen generate --spec-dir $out/spec --out $out/generated
$k generate --spec-dir $out/spec --out $out/generated
# the CasADi cross-check needs its pinned Python tooling (PyPI)
python3 -m pip install --quiet --disable-pip-version-check -r verify/casadi/requirements.txt 2>/dev/null \
  || echo "(could not install the CasADi tooling: verify will skip its CasADi cross-check)"
say kinegen verify --spec $out/spec/diff_drive.toml --samples 50
$k verify --spec $out/spec/diff_drive.toml --samples 50

echo
echo "reports: $out/compare/index.html $out/diagnose/index.html $out/fit-before/index.html $out/fit-after/index.html"
