#!/bin/bash
# Usage: tools/compare_runs.sh OLD_SIM NEW_SIM [run|mission]
# A structural change must leave a seeded run's outputs byte-identical (issue 28). This runs the same
# seeded `run` (30 s, 2 robots, --record full) or `mission` (60 s) with two airground-sim binaries and
# compares every file, except the wall times: report.md and summary.* are skipped, metrics.json without
# its realtime_factor/wall_s lines, mission_log.jsonl without "utc" and sorted (lines of one instant are
# written by several threads). Prints IDENTICAL, or a DIFF line per file; exit 0 only when identical.
# Copy the old binary aside before rebuilding (cp build/native/sim/airground-sim /tmp/old-sim).
set -euo pipefail
if [ $# -lt 2 ] || [ "$1" = "--help" ]; then sed -n 2,8p "$0" | sed 's/^# \{0,1\}//'; exit 2; fi
old=$1; new=$2; kind=${3:-run}
work=$(mktemp -d /tmp/compare_runs.XXXXXX)
trap 'rm -rf "$work"' EXIT
for side in old new; do
  bin=${!side}
  case $kind in
    run) args=(run --world default --ugvs 2 --seed 3 --duration 30 --record full) ;;
    mission) args=(mission --world default --ugvs 2 --seed 3 --max-duration 60) ;;
    *) echo "compare_runs: unknown kind '$kind' (run or mission)" >&2; exit 2 ;;
  esac
  echo "compare_runs: $side: $bin ${args[*]}" >&2
  nice "$bin" "${args[@]}" --out "$work/$side" > "$work/$side.log" 2>&1 || { echo "compare_runs: $side failed (log: $work/$side.log)" >&2; cat "$work/$side.log" >&2; exit 1; }
done
bad=0
cd "$work/old"
for f in $(find . -type f | sort); do
  case $f in ./report.md|./summary.json|./summary.yaml) continue ;; esac
  if [ ! -f "$work/new/$f" ]; then echo "DIFF $f (missing in new)"; bad=1; continue; fi
  case $f in
    ./mission_log.jsonl) cmp -s <(sed 's/"utc":[0-9.]*,//' "$f" | sort) <(sed 's/"utc":[0-9.]*,//' "$work/new/$f" | sort) || { echo "DIFF $f"; bad=1; } ;;
    ./metrics.json) cmp -s <(grep -v -E '"(realtime_factor|wall_s)"' "$f") <(grep -v -E '"(realtime_factor|wall_s)"' "$work/new/$f") || { echo "DIFF $f"; bad=1; } ;;
    *) cmp -s "$f" "$work/new/$f" || { echo "DIFF $f"; bad=1; } ;;
  esac
done
[ $bad = 0 ] && echo IDENTICAL
exit $bad
