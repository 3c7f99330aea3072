#!/usr/bin/env bash
# Memory and report size of `kinegen compare` and `kinegen fit` on a long log
# (issue 16, item 9: a 200 MB log in under 500 MB of memory, a report under
# 5 MB; issue 11 item 5: memory independent of the log's length beyond the log).
#
# Simulates a ~200 MB diff-drive log and a log a tenth as long, runs compare
# and fit with a report on both, and prints peak resident memory (GNU time), report
# size and the ratio of peak memory to log size: the short log is the baseline
# of the same run, so the ratio shows whether memory grows with the log or
# with the data kinegen keeps per row.
#
# fit runs twice: with its default likelihood (the whole run) and with
# `--likelihood segments` (issue 66 item 7: 1M rows within 8 s and 200 MiB),
# each with its wall time.
#
# Usage: scripts/bench_memory.sh [KINEGEN_BINARY]   (default: target/release/kinegen)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="${1:-$root/target/release/kinegen}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
spec="$root/spec/diff_drive.toml"

run() { # laps label: prints, per command, peak memory; sets rows_$2, rss_<cmd>_$2
  local log="$work/$2.csv"
  "$bin" simulate --spec "$spec" --trajectory random --laps "$1" --out "$log" >/dev/null 2>&1
  local mb_log rss_kb report_kb rows
  mb_log=$(( $(stat -c %s "$log") / 1000000 ))
  rows=$(( $(wc -l < "$log") - 1 ))
  eval "rows_$2=$rows"
  for cmd in compare fit fit_segments; do
    local args=("${cmd%_segments}")
    [ "$cmd" = fit_segments ] && args+=(--likelihood segments)
    read -r rss_kb wall < <(/usr/bin/time -f "%M %e" "$bin" "${args[@]}" --spec "$spec" --data "$log" \
      --report "$work/$2-$cmd" --json "$work/$2-$cmd.json" 2>&1 >/dev/null | tail -1)
    report_kb=$(du -sk "$work/$2-$cmd" | cut -f1)
    eval "rss_${cmd}_$2=$rss_kb"
    printf '%-12s %-6s log %4d MB (%8d rows)  %6.1f s  peak memory %5d MB  report %5d kB  memory/log %.2f\n' \
      "$cmd" "$2" "$mb_log" "$rows" "$wall" $((rss_kb / 1000)) "$report_kb" \
      "$(echo "$rss_kb / 1000 / $mb_log" | bc -l)"
  done
  rm -f "$log"
}

run 130 short
run 1300 long
# what each extra row of log costs: the log as read plus whatever the command
# keeps per row (the second term is what should not grow with the log)
for cmd in compare fit fit_segments; do
  eval "a=\$rss_${cmd}_short b=\$rss_${cmd}_long"
  printf '%-12s %.0f bytes of peak memory per row of log\n' "$cmd" \
    "$(echo "($b - $a) * 1000 / ($rows_long - $rows_short)" | bc -l)"
done
