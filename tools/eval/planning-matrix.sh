#!/usr/bin/env bash
# Issue 6's planning figures: the default world and two generated worlds (500 m seed 7, 600 m seed 23),
# 20 random reachable pairs each: route length against the 8-connected grid optimum, clearance, and
# every route driven on the simulated robot with the ground-truth pose. One line per world.
# Usage: tools/eval/planning-matrix.sh [OUT] [extra eval options, e.g. --set planner.clearance_gain_m=2]
set -euo pipefail
top=$(cd "$(dirname "$0")/../.." && pwd)
sim=${AG_SIM:-$top/build/native/sim/airground-sim}
out=${1:-$top/build/eval/planning}
shift || true
mkdir -p "$out"
[ -f "$out/world7/world.yaml" ] || "$sim" world generate --seed 7 --size 500 --targets 13 --out "$out/world7" >/dev/null
[ -f "$out/world23/world.yaml" ] || "$sim" world generate --seed 23 --size 600 --targets 13 --out "$out/world23" >/dev/null
printf '%-10s %5s %10s %9s %10s %8s %10s %7s %9s %8s %8s\n' world pairs ratio_mean ratio_max clear_mean reached collisions failures blocked build_ms query_ms
for w in default "$out/world7" "$out/world23"; do
  name=$(basename "$w")
  d="$out/$name"
  [ "$w" = default ] && d="$out/default"
  "$sim" eval planning --world "$w" --seed 2 --pairs 20 --out "$d" --quiet "$@" >"$d.log" 2>&1 || true
  /usr/bin/python3 - "$d/metrics.json" "$name" <<'PY'
import json, sys
try:
    m = json.load(open(sys.argv[1]))
except Exception as e:
    print(f"{sys.argv[2]:<10} failed: {e}"); sys.exit(0)
print(f"{sys.argv[2]:<10} {m['pairs']:5d} {m['path_length_ratio_mean']:10.3f} {m['path_length_ratio_max']:9.3f} {m['min_clearance_ratio_mean']:10.2f} "
      f"{m['reached']:8d} {m['collisions']:10d} {m['failures']:7d} {m['through_blocked'] + m['too_close']:9d} {m['build_ms']:8.0f} {m['query_ms_mean']:8.2f}")
PY
done
