#!/usr/bin/env bash
# Issue 27's field-mode study on its three worlds (docs/study/README.md), resumable: run it again with the
# same --out and every mission that already has metrics.json is skipped.
#
# The quadrotor is recorded once per world, seed and altitude and replayed in every later mission. The
# recording's key hashes the simulator executable, so the script keeps two frozen copies in OUT/bin:
# `recorder` (the build that records, copied on the first run) and `airground-sim` (the build that runs
# the missions, replaced by --bin). When they differ, the missions replay the recorder's recordings
# (--uav-cache-build); a change to any quadrotor stage needs a new OUT (or --new-recorder).
set -euo pipefail

usage() {
  cat <<'EOF'
tools/field_study.sh — the field-mode study (issue 27) on the default world, the imported 200 m map and gen6

Usage: tools/field_study.sh [--out DIR] [--bin EXE] [--worlds default,imported,gen6] [--ugvs 1,2,3,5,10]
                            [--seeds 1,2] [--comm-range R[,R...]] [--new-recorder] [--dry-run]

  --out DIR          everything goes here (study-field): bin/, worlds/, <world>/runs/..., <world>/study.md, logs/
  --bin EXE          the airground-sim that runs the missions (build/native/sim/airground-sim)
  --worlds LIST      which worlds, in order (default,imported,gen6)
  --ugvs LIST        team sizes, in order (1,2,3,5,10): the first mission of a seed records the quadrotor
  --seeds LIST       seeds (1,2), run at once, one mission at a time each (two cores)
  --comm-range LIST  radio ranges [m] (default world: 150,1000,50; the others: 150, as in docs/study)
  --new-recorder     record the quadrotor anew with --bin (after a change to a quadrotor stage)
  --dry-run          print the commands only

Each world's table and plots: DIR/<world>/study.md (rewritten at the end of each world by
'study --report-only'); each mission's report: DIR/<world>/runs/<world>_u<N>_r<R>_s<S>/report.md.
EOF
}

OUT=study-field
BIN=build/native/sim/airground-sim
WORLDS=default,imported,gen6
UGVS=1,2,3,5,10
SEEDS=1,2
RANGES=
NEW_RECORDER=0
DRY=0
while [ $# -gt 0 ]; do
  case "$1" in
    -h|--help) usage; exit 0 ;;
    --out) OUT=$2; shift 2 ;;
    --bin) BIN=$2; shift 2 ;;
    --worlds) WORLDS=$2; shift 2 ;;
    --ugvs) UGVS=$2; shift 2 ;;
    --seeds) SEEDS=$2; shift 2 ;;
    --comm-range) RANGES=$2; shift 2 ;;
    --new-recorder) NEW_RECORDER=1; shift ;;
    --dry-run) DRY=1; shift ;;
    *) echo "field_study.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[ -x "$BIN" ] || { echo "field_study.sh: --bin $BIN: no such executable (build it: make build)" >&2; exit 2; }

run() { echo "+ $*"; [ "$DRY" = 1 ] || "$@"; }

mkdir -p "$OUT/bin" "$OUT/worlds" "$OUT/logs"
if [ ! -x "$OUT/bin/recorder" ] || [ "$NEW_RECORDER" = 1 ]; then cp "$BIN" "$OUT/bin/recorder"; fi
cmp -s "$BIN" "$OUT/bin/airground-sim" 2>/dev/null || cp "$BIN" "$OUT/bin/airground-sim"
SIM=$OUT/bin/airground-sim
REPLAY=()
cmp -s "$OUT/bin/recorder" "$SIM" || REPLAY=(--uav-cache-build "$OUT/bin/recorder")

# The worlds of docs/study/README.md ("Other worlds").
world_dir() {
  case "$1" in
    default) echo default ;;
    imported)
      local w=$OUT/worlds
      if [ ! -f "$w/imported/world.yaml" ]; then
        run "$SIM" world generate --seed 7 --size 200 --targets 6 --out "$w/gen7-200" >&2
        printf 'classes:\n  - {value: 0, class: road}\n  - {value: 1, class: dirt}\n  - {value: 2, class: grass}\n  - {value: 3, class: tree}\n  - {value: 4, class: building}\n  - {value: 5, class: vehicle}\n  - {value: 6, class: water}\n' >"$w/legend.yaml"
        run "$SIM" world import --classes "$w/gen7-200/class.png" --legend "$w/legend.yaml" --resolution 0.25 --out "$w/imported" >&2
      fi
      echo "$w/imported" ;;
    gen6)
      [ -f "$OUT/worlds/gen6/world.yaml" ] || run "$SIM" world generate --seed 6 --size 400 --out "$OUT/worlds/gen6" >&2
      echo "$OUT/worlds/gen6" ;;
    *) echo "field_study.sh: unknown world '$1' (default, imported, gen6)" >&2; exit 2 ;;
  esac
}

IFS=, read -r -a world_list <<<"$WORLDS"
IFS=, read -r -a seed_list <<<"$SEEDS"
for world in "${world_list[@]}"; do
  wdir=$(world_dir "$world")
  ranges=${RANGES:-$([ "$world" = default ] && echo 150,1000,50 || echo 150)}
  dir=$OUT/$world
  pids=()
  for seed in "${seed_list[@]}"; do
    log=$OUT/logs/${world}_s$seed.log
    echo "== $world seed $seed: ugvs $UGVS, ranges $ranges -> $dir (log $log)"
    cmd=("$SIM" study --worlds "$wdir" --ugvs "$UGVS" --comm-range "$ranges" --seeds 1 --first-seed "$seed" --jobs 1
         --altitude 60 --lidar-columns 512 --max-duration 5400 "${REPLAY[@]}" --out "$dir")
    if [ "$DRY" = 1 ]; then echo "+ ${cmd[*]}"; else "${cmd[@]}" >>"$log" 2>&1 & pids+=($!); fi
  done
  status=0
  for p in "${pids[@]}"; do wait "$p" || status=$?; done
  run "$SIM" study --worlds "$wdir" --ugvs "$UGVS" --comm-range "$ranges" --seeds "${#seed_list[@]}" --first-seed "${seed_list[0]}" --report-only --out "$dir" >/dev/null
  [ "$status" = 0 ] || echo "field_study.sh: a $world study exited with $status (see $OUT/logs)" >&2
done
