#!/usr/bin/env bash
# The whole test suite, as CI runs it (.ci/run calls this script).
#  1. install the Python tooling of the CasADi cross-check and of the bag tests
#     (pinned versions)
#  2. regenerate the CasADi reference fixtures (and the peer benchmark's
#     CasADi, wrenfold and SymForce kernels)
#     from the specs and fail if they differ from the committed ones (the
#     check is live, not frozen)
#  3. build the guide (docs/, mdBook) and fail if generated/ is stale
#     (kinegen generate --check)
#  4. cargo test over the whole workspace, then the Python package (pip
#     install ./python, pytest, its example), then a short campaign of
#     hostile inputs (scripts/hostile_campaign.py). Tests that use symbolica run it only in
#     child processes that queue on a machine-wide lock, so the default parallel
#     test runner is safe; do not use cargo-nextest (it runs tests as processes
#     in parallel, which is also safe here, but is not what this project tests).
#  Tests on real robot logs read ../shared/real/ (or $KINEGEN_REAL_DATA); a
#  clone without it passes, and each skipped test prints a SKIPPED line.
set -euo pipefail
cd "$(dirname "$0")/.."
started=$(date +%s)
# Each stage's wall time, printed as a table at the end (CI's log shows where
# the command's minutes go; the target is 15 minutes on 2 cores)
stages=""
timed() { # label, then the command
  local label="$1" t0
  shift
  t0=$(date +%s)
  "$@"
  stages+="$(printf '%-34s %5d s' "$label" $(( $(date +%s) - t0 )))"$'\n'
}
real="${KINEGEN_REAL_DATA:-../shared/real}"
if [ ! -d "$real" ]; then
  echo "note: no real robot logs at $real: the real-data tests will print SKIPPED and pass without checking"
fi
# Some containers ship /dev/null as a plain file: whatever a program sends
# there stays (Chromium's launcher, run by the report test, sends an `ls` error
# there), and cargo's rustc probe, which reads /dev/null as source, then fails
# in every fresh target directory (the generated-crate tests). Put the
# character device back when we may.
if [ ! -c /dev/null ]; then
  if mknod -m 666 /dev/null.kinegen c 1 3 2>/dev/null && mv -f /dev/null.kinegen /dev/null; then
    echo "note: /dev/null was a plain file; restored the null device"
  else
    echo "warning: /dev/null is a plain file here and could not be restored; the generated-crate tests may fail" >&2
  fi
fi
timed "pip (pinned Python tools)" python3 -m pip install --quiet --disable-pip-version-check -r verify/casadi/requirements.txt -r verify/bags/requirements.txt -r verify/peers/requirements.txt -r verify/precision/requirements.txt -r verify/batch/requirements.txt -r verify/init/requirements.txt -r python/requirements-test.txt -r docs/requirements.txt
timed "CasADi fixtures" python3 verify/casadi/reference.py --check
timed "wrenfold peer kernels" python3 verify/peers/wrenfold_kernels.py --check
timed "SymForce peer kernels" python3 verify/peers/symforce_kernels.py --check
timed "CasADi peer kernels" python3 verify/casadi/reference.py --check-c
timed "precision references" python3 verify/precision/reference.py --check
# the guide (mdBook): its internal links are checked by tests/docs.rs
# pip puts mdbook in Python's scripts folder, which need not be on the PATH
mdbook="$(python3 -c 'import sysconfig; print(sysconfig.get_path("scripts"))')/mdbook"
[ -x "$mdbook" ] || mdbook=mdbook
timed "the guide (mdBook)" "$mdbook" build docs
# pyo3's build script reads these two; maturin sets them when it builds the
# Python package below: set the same here, so that the package reuses this
# build's pyo3 instead of compiling it (and rebuilding this one) again
PYO3_PYTHON="$(python3 -c 'import sys; print(sys.executable)')"
PYO3_ENVIRONMENT_SIGNATURE="$(python3 -c 'import platform, sys; print(f"cpython-{sys.version_info[0]}.{sys.version_info[1]}-{platform.architecture()[0]}")')"
export PYO3_PYTHON PYO3_ENVIRONMENT_SIGNATURE
timed "cargo build (workspace)" cargo build --workspace --all-targets
# the binary the workspace build just made: `cargo run --bin kinegen` resolves
# features for the one package and would compile symbolica a second time (~10 min)
timed "generate --check" "${CARGO_TARGET_DIR:-target}/debug/kinegen" generate --check
# The tests that derive with symbolica (tests/autodiff.rs and
# tests/generate.rs, `symbolic_stage::`) hold its machine-wide lock on one
# thread: on 2 cores they run beside the others, not alone, which saves most
# of their 45 s. cargo keeps its build lock while its tests run, so they run
# as the binaries cargo built (from the root folder, as cargo would).
# (--workspace: the features the workspace build resolved, so nothing is
# compiled again; without it cargo resolved the root package's alone and
# built a second kinegen and its tests, 2 minutes on a fresh clone)
symbolic_bins=$(cargo test --workspace --test autodiff --test generate --no-run --message-format=json 2>/dev/null \
  | python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        print(m["executable"])')
beside_log="$(mktemp)"
(
  t0=$(date +%s) rc=0
  for b in $symbolic_bins; do "$b" symbolic_stage:: || rc=1; done
  echo "symbolic-stage tests (beside): $(( $(date +%s) - t0 )) s"
  exit $rc
) >"$beside_log" 2>&1 &
beside=$!
trap 'kill $beside 2>/dev/null; rm -f "$beside_log"' EXIT
timed "cargo test (workspace)" cargo test --workspace -- --skip symbolic_stage::
beside_rc=0
wait $beside || beside_rc=$?
trap - EXIT
# their results (symbolica's own warnings, thousands of lines, only when
# they failed)
if [ "$beside_rc" = 0 ]; then grep -E "^(test |running|test result)|beside" "$beside_log"; else cat "$beside_log"; fi
stages+="$(tail -1 "$beside_log")"$'\n'
rm -f "$beside_log"
[ "$beside_rc" = 0 ] || { echo "scripts/test.sh: the symbolic-stage tests failed (above)" >&2; exit 1; }
# the Python package (maturin, the dev profile: it reuses the workspace's
# build), its tests against the command line, and its story example
timed "Python package (build)" python3 -m pip install --quiet --disable-pip-version-check --no-build-isolation ./python
KINEGEN_BIN="${CARGO_TARGET_DIR:-target}/debug/kinegen" timed "Python package (tests)" python3 -m pytest -q python/tests
timed "Python story example" python3 python/examples/story.py "${TMPDIR:-/tmp}/kinegen-story.png"
# 400 hostile inputs over every command (about 15 s; the guide's results run
# 2,000 a seed): no panic, abort, hang, unlocated error, stray file or NaN
timed "hostile campaign" python3 scripts/hostile_campaign.py --bin "${CARGO_TARGET_DIR:-target}/debug/kinegen" --cases 400 --seed 3
printf "\nwhere the time went:\n%s" "$stages"
echo "scripts/test.sh: the whole suite took $(( $(date +%s) - started )) s"
