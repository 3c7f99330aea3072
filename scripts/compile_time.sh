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
# With --story, it runs the README's first command (scripts/story.sh) in the
# fresh clone instead, as a newcomer would, and prints when diagnose's
# answer appeared and when the story ended, counted from the start (its
# builds included).
#
# Usage: scripts/compile_time.sh [--keep] [--no-tests] [--story]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
keep=0 tests=1 story=0
for a in "$@"; do
  case "$a" in
    --keep) keep=1 ;;
    --no-tests) tests=0 ;;
    --story) story=1 ;;
    *) echo "usage: scripts/compile_time.sh [--keep] [--no-tests] [--story]" >&2; exit 2 ;;
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

if [ "$story" = 1 ]; then
  # each line of the story's output stamped with the seconds since the start
  start=$(date +%s.%N)
  /usr/bin/time -f "%e %U %S" -o "$work/time-story" bash scripts/story.sh 2>&1 \
    | while IFS= read -r line; do
        awk -v now="$(date +%s.%N)" -v t0="$start" -v l="$line" 'BEGIN { printf "%7.1f %s\n", now - t0, l }'
      done >"$work/log-story"
  read -r wall user sys <"$work/time-story"
  answer=$(grep -m1 -E '^ *[0-9.]+ answer: missing' "$work/log-story" | awk '{print $1}')
  awk -v a="${answer:--1}" 'BEGIN { if (a < 0) print "diagnose printed no answer"; else printf "diagnose answer after %6.1f min\n", a / 60 }'
  awk -v w="$wall" -v u="$user" -v s="$sys" \
    'BEGIN { printf "story ended after  %6.1f min wall %6.1f CPU-min\n", w / 60, (u + s) / 60 }'
  grep -m1 'answer: missing' "$work/log-story"
  [ "$keep" = 1 ] && echo "kept: $work/kinegen (the story's output, stamped: $work/log-story)"
  exit 0
fi

stage "light (the analysis)" cargo build --locked --no-default-features --bin kinegen --timings
stage "full (symbolica)" cargo build --locked --bin kinegen --timings
if [ "$tests" = 1 ]; then
  stage "tests (workspace)" cargo build --locked --workspace --all-targets --timings
fi
if [ "$keep" = 1 ]; then
  echo "kept: $work/kinegen (timings in target/cargo-timings)"
fi
