#!/usr/bin/env bash
# The kernel benchmark against its peers (issue 66 item 5): runs
# `cargo bench -p kinegen-peers` in the generic build and in the native one
# (`-C target-cpu=native`, how firmware and x86 users build), each measuring
# in 3 processes one after the other (thread CPU time; every cell the
# median and range over the processes), and writes what
# the bench prints, verbatim, under a provenance header (date, commit,
# machine, load, build, the command), to the page the guide includes
# (docs/src/results/peers-table.md). No figure of it is typed by hand.
#
# Usage: scripts/bench_peers.sh [OUT.md]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/docs/src/results/peers-table.md}"
cd "$root"
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs)
tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
{
  echo "<!-- written by scripts/bench_peers.sh: do not edit; rerun it -->"
  # the page itself is not a local change of the code measured
  echo "Provenance: $(date -u +%F), commit $(git rev-parse --short HEAD)$(git diff --quiet HEAD -- . ":(exclude)$out" || echo ' (with local changes)'),"
  echo "$(nproc) cores of \`$cpu\`, load average $(cut -d' ' -f1-3 /proc/loadavg) before the runs,"
  echo "$(rustc --version). Reproduce with \`scripts/bench_peers.sh\`."
  for build in generic native; do
    echo
    if [ "$build" = native ]; then
      echo "### Native build (\`RUSTFLAGS=\"-C target-cpu=native\" cargo bench -p kinegen-peers\`)"
      flags="-C target-cpu=native" target="$root/target/native"
    else
      echo "### Generic build (\`cargo bench -p kinegen-peers\`)"
      flags="" target="${CARGO_TARGET_DIR:-$root/target}"
    fi
    echo
    RUSTFLAGS="$flags" CARGO_TARGET_DIR="$target" cargo bench -q -p kinegen-peers 2>/dev/null \
      | grep -v -E '^(running [0-9]+ tests?|test result: |[.i]+$)' | cat -s \
      | sed 's/^left out: /- left out: /; s/^inputs: /- inputs: /'
  done
} >"$tmp"
mv "$tmp" "$out"
trap - EXIT
echo "wrote $out"
