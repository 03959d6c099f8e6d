#!/usr/bin/env bash
# Issue 5's localization figures: the default world and two generated worlds, three evaluation seeds
# each, 2 km of road with the initial guess 16 m / 30 deg off; prints one line per run and a table
# (results in OUT/<world>-s<seed>/metrics.json, trajectory.png, error.png).
# Usage: tools/eval/localization-matrix.sh [OUT] [extra eval options, e.g. --map online or --labels geometric]
set -euo pipefail
top=$(cd "$(dirname "$0")/../.." && pwd)
sim=${AG_SIM:-$top/build/native/sim/airground-sim}
out=${1:-$top/build/eval/localization}
shift || true
mkdir -p "$out"
worlds=(default)
for ws in 2 3; do
  [ -f "$out/world$ws/world.yaml" ] || "$sim" world generate --seed "$ws" --size 400 --out "$out/world$ws" >/dev/null
  worlds+=("$out/world$ws")
done
printf '%-10s %4s %9s %8s %8s %8s %8s %10s %6s\n' world seed converged conv_s mean_m p95_m yaw_deg odom_m div
for w in "${worlds[@]}"; do
  name=$(basename "$w")
  for s in 1 2 3; do
    d="$out/$name-s$s"
    "$sim" eval localization --world "$w" --seed "$s" --init-error 16 --route-km "${AG_ROUTE_KM:-2}" --out "$d" --quiet "$@" >"$d.log" 2>&1 || true
    /usr/bin/python3 - "$d/metrics.json" "$name" "$s" <<'PY'
import json, sys
try:
    m = json.load(open(sys.argv[1]))
except Exception as e:
    print(f"{sys.argv[2]:<10} {sys.argv[3]:>4} failed: {e}"); sys.exit(0)
print(f"{sys.argv[2]:<10} {sys.argv[3]:>4} {str(m['converged']):>9} {m['convergence_time_s']:8.1f} {m['loc_error_mean_m']:8.2f} "
      f"{m['loc_error_p95_m']:8.2f} {m['yaw_error_mean_deg']:8.2f} {m['odom_only_error_mean_m']:10.1f} {m['divergences']:6d}")
PY
  done
done
