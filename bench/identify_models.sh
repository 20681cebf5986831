#!/usr/bin/env bash
# Whole identification cases on other bundled models than the rotary
# pendulum: each model clean (nothing should be named) and with one hidden
# effect, made by `plantc synth` (sticking dry friction, 500 Hz,
# 4096-count encoders, the rig off the model's values), then `plantc
# identify`. Prints wall and CPU time (user + sys), the effects named and
# where the story stopped, with the machine's load when the case ended.
# The pendubot's driven record tumbles (chaotic motion: see
# identify/tests/chaotic_records.rs).
#
#   bash bench/identify_models.sh               # every case
#   bash bench/identify_models.sh pb_clean      # some of them, by name
#
# PLANTC=path/to/plantc skips the cargo build.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
if [ -z "${PLANTC:-}" ]; then
    cargo build --quiet --release -p plantc
    PLANTC="$target/release/plantc"
fi
dir="$target/bench-identify-models"
mkdir -p "$dir"

cp="--set mc=1.2 --set l=0.45 --set bx=0.15 --experiment free_swing:th0=150deg,duration=10 --experiment driven:th0=180deg,duration=10,rms=2,band=0.3-5,seed=2"
pb="--set I1=8e-4 --set b2=2e-4 --experiment free_swing:q10=170deg,q20=30deg,duration=10 --experiment driven:q10=180deg,duration=10,rms=0.2,band=0.3-5,seed=2"
qs="--set Jr=2.6e-4 --set bp=8e-5 --experiment free_swing:alpha0=150deg,duration=10 --experiment driven:alpha0=180deg,duration=10,rms=1.5,band=0.3-5,seed=2"
# name | model | synth options
cases=(
    "cp_clean|cart_pole|$cp"
    "cp_coulomb|cart_pole|$cp --effect coulomb_friction:x=0.3"
    "pb_clean|pendubot|$pb"
    "pb_coulomb|pendubot|$pb --effect coulomb_friction:q2=5e-4"
    "qs_clean|qube_servo|$qs"
    "qs_coulomb|qube_servo|$qs --effect coulomb_friction:alpha=1e-4"
    "qs_spring|qube_servo|$qs --effect spring:theta=5e-3"
)

printf '%-12s %7s %7s %5s  %s\n' case "wall s" "CPU s" load "effects named; stop"
for entry in "${cases[@]}"; do
    IFS='|' read -r name model opts <<<"$entry"
    if [ $# -gt 0 ] && ! printf '%s\n' "$@" | grep -qx "$name"; then
        continue
    fi
    # shellcheck disable=SC2086
    "$PLANTC" synth "models/$model.plant" $opts --seed 1 --case "$name" \
        -o "$dir/$name" --force >/dev/null
    /usr/bin/env time -f "%e %U %S" -o "$dir/$name.time" \
        "$PLANTC" identify "models/$model.plant" "$dir/$name"/*.csv \
        -o "$dir/$name-out" --force --json >"$dir/$name.json" 2>"$dir/$name.err" || {
        printf '%-12s failed: see %s\n' "$name" "$dir/$name.err"
        continue
    }
    read -r wall user sys <"$dir/$name.time"
    cpu=$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')
    named=$(python3 -c '
import json, sys
d = json.load(open(sys.argv[1]))
effects = [r["effect"] for r in d["rounds"] if r.get("effect")]
print((", ".join(effects) or "none") + "; " + d["stop"])
' "$dir/$name.json" 2>/dev/null || grep -o '"stop": "[^"]*"' "$dir/$name.json" | cut -d'"' -f4)
    printf '%-12s %7s %7s %5s  %s\n' "$name" "$wall" "$cpu" "$(cut -d' ' -f1 /proc/loadavg)" "$named"
done
