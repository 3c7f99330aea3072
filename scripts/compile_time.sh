#!/usr/bin/env bash
# The story's compile cost from a fresh clone (issue 66, item 8; issue 71):
# clones this checkout's HEAD into a temporary folder and builds what
# scripts/story.sh builds, in its order, with an empty target folder and the
# cargo registry as it is (warm on a machine that has built kinegen once):
#   1. the light binary (`--no-default-features`): the analysis, the answer;
#   2. the full binary (symbolica): generate and verify;
#   3. the workspace's tests (`scripts/test.sh`'s build).
# Prints, per stage, wall time and CPU-minutes (user + system of cargo and
# everything it ran), and writes cargo's timings report of each stage
# (target/cargo-timings in the clone, kept when --keep is given).
#
# Usage: scripts/compile_time.sh [--keep] [--no-tests]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
keep=0 tests=1
for a in "$@"; do
  case "$a" in
    --keep) keep=1 ;;
    --no-tests) tests=0 ;;
    *) echo "usage: scripts/compile_time.sh [--keep] [--no-tests]" >&2; exit 2 ;;
  esac
done
work="$(mktemp -d)"
[ "$keep" = 1 ] || trap 'rm -rf "$work"' EXIT
git clone --quiet "$root" "$work/kinegen"
cd "$work/kinegen"
commit="$(git rev-parse --short HEAD)"
echo "compile time of commit $commit, $(nproc) cores ($(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)), $(date -u +%Y-%m-%d)"

stage() { # label, then the cargo command
  local label="$1"; shift
  local t="$work/time-$label"
  /usr/bin/time -f "%e %U %S" -o "$t" "$@" >"$work/log-$label" 2>&1 || {
    echo "$label: FAILED (log: $work/log-$label)"; tail -20 "$work/log-$label"; keep=1; exit 1; }
  read -r wall user sys <"$t"
  awk -v l="$label" -v w="$wall" -v u="$user" -v s="$sys" \
    'BEGIN { printf "%-28s %6.1f min wall %6.1f CPU-min\n", l, w / 60, (u + s) / 60 }'
}

stage "light (the analysis)" cargo build --locked --no-default-features --bin kinegen --timings
stage "full (symbolica)" cargo build --locked --bin kinegen --timings
if [ "$tests" = 1 ]; then
  stage "tests (workspace)" cargo build --locked --workspace --all-targets --timings
fi
if [ "$keep" = 1 ]; then
  echo "kept: $work/kinegen (timings in target/cargo-timings)"
fi
