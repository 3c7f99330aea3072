#!/usr/bin/env bash
# Memory and report size of `kinegen compare` on a long log (issue 16, item 9:
# a 200 MB log in under 500 MB of memory, a report under 5 MB).
#
# Simulates a ~200 MB diff-drive log and a log a tenth as long, runs compare
# with a report on both, and prints peak resident memory (GNU time), report
# size and the ratio of peak memory to log size: the short log is the baseline
# of the same run, so the ratio shows whether memory grows with the log or
# with the data kinegen keeps per row.
#
# Usage: scripts/bench_memory.sh [KINEGEN_BINARY]   (default: target/release/kinegen)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${1:-$root/target/release/kinegen}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
spec="$root/spec/diff_drive.toml"

run() { # laps label
  local log="$work/$2.csv"
  "$bin" simulate --spec "$spec" --trajectory random --laps "$1" --out "$log" >/dev/null 2>&1
  local mb_log rss_kb report_kb
  mb_log=$(( $(stat -c %s "$log") / 1000000 ))
  rss_kb=$(/usr/bin/time -f %M "$bin" compare --spec "$spec" --data "$log" \
    --report "$work/$2-report" --json "$work/$2.json" 2>&1 >/dev/null | tail -1)
  report_kb=$(du -sk "$work/$2-report" | cut -f1)
  printf '%-6s log %4d MB  peak memory %5d MB  report %5d kB  memory/log %.2f\n' \
    "$2" "$mb_log" $((rss_kb / 1000)) "$report_kb" \
    "$(echo "$rss_kb / 1000 / $mb_log" | bc -l)"
  rm -f "$log"
}

run 130 short
run 1300 long
