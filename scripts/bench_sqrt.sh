#!/usr/bin/env bash
# The generated crate's square root against libm's in a generic and a native
# (`-C target-cpu=native`) build, with clean and dirty upper vector halves
# (issue 66, item 1). Each build runs three processes of each state; the
# processes' own lines, then the markdown table of the guide's speed page
# (docs/src/results/speed.md), made from them.
# Usage: scripts/bench_sqrt.sh
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
crate="$root/verify/sqrt_encoding"
target="$root/target/sqrt-encoding"
echo "commit $(git -C "$root" rev-parse --short HEAD), $(date -u +%Y-%m-%d), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), load $(cut -d' ' -f1-3 /proc/loadavg)"
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
for build in generic native; do
  flags=""
  [ "$build" = native ] && flags="-C target-cpu=native"
  RUSTFLAGS="$flags" cargo build --quiet --release --manifest-path "$crate/Cargo.toml" --target-dir "$target/$build"
  for state in clean dirty; do
    for _ in 1 2 3; do "$target/$build/release/kinegen-sqrt-encoding" "$state" | tee -a "$log"; done
  done
done
echo
echo "| build | kernel | median ns per call, three processes |"
echo "|---|---|---|"
awk '/^build:/ { sub(/^build: /, ""); sub(/; upper halves/, ", upper halves"); b = $0; next }
     { name = substr($0, 3, 32); sub(/ +$/, "", name); k = b " | " name
       if (!(k in m)) { order[++n] = k; m[k] = $(NF - 5) } else m[k] = m[k] " / " $(NF - 5) }
     END { for (i = 1; i <= n; i++) print "| " order[i] " | " m[order[i]] " |" }' "$log"
