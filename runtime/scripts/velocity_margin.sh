#!/usr/bin/env bash
# Measures which velocity estimators let `plantc run` (sim backend, 1 kHz,
# 4096-count encoders, ZOH, +-10 V) catch the rotary pendulum from 5 deg and
# balance it for 30 s, for pole_placement and fl_arm with a = b.
#
# Prints, per estimator and controller, the largest |alpha| (deg) over the
# last 5 s when the supervisor is still engaged at 30 s, or the fault and the
# second it happened (arm@3: arm limit at 3 s, fell@2: pendulum fell at 2 s). Usage (from the workspace root, after `cargo build --release -p plantc`):
#   runtime/scripts/velocity_margin.sh [--set thesis]
set -euo pipefail
P=${PLANTC:-target/release/plantc}
M=models/rotary_pendulum.plant
SET=("$@")
LOG=$(mktemp --suffix=.csv)
trap 'rm -f "$LOG"' EXIT
GAINS=(0.05 0.1 0.3 0.5 0.7 0.9 0.95)
printf '%-44s %-8s' "estimator" "pole_pl"
for g in "${GAINS[@]}"; do printf ' %-8s' "a=$g"; done
echo
for est in "observer --observer-accel 10" "observer --observer-accel 30" "observer --observer-accel 100" \
           "derivative --velocity-bandwidth 50" "derivative --velocity-bandwidth 100" \
           "derivative --velocity-bandwidth 200" "derivative --velocity-bandwidth 400" \
           "derivative --velocity-bandwidth 1000"; do
  printf '%-44s' "$est"
  for c in pole_placement "${GAINS[@]}"; do
    if [ "$c" = pole_placement ]; then ctl=(--controller pole_placement); else ctl=(--controller fl_arm --gain "a=$c,b=$c"); fi
    # shellcheck disable=SC2086
    "$P" run "$M" "${SET[@]}" "${ctl[@]}" --velocity $est --x0 alpha=5deg --duration 30 \
      --log "$LOG" --force >/dev/null 2>&1 || true
    awk -F, 'NR > 1 { st = $10; t = $1; if ($1 >= 25) { w = $3 < 0 ? -$3 : $3; if (w > m) m = w } }
      END { if (st == "engaged") printf " %-8.2f", m * 57.29578
            else { f = substr(st, 7); sub("_limit", "", f); sub("pendulum_fell", "fell", f); printf " %-8s", f "@" int(t) } }' "$LOG"
  done
  echo
done
