#!/usr/bin/env bash
# Whole identification cases, one per hidden effect, against the 3 s CPU goal
# of issue 11 (item 6: nominal fit, diagnose, apply, refit, 3 x 10,000
# samples).
#
#   bash bench/identify_cases.sh            # every case
#   bash bench/identify_cases.sh spring two # some of them, by name
#
# Each case is made here by `plantc synth` with the settings of
# bench/identify_vs_scipy.sh (the rotary pendulum at values off nominal;
# free_swing_large, free_swing_small and driven, 20 s at 500 Hz, 4096-count
# encoders) and one hidden effect, or none, or two (`two`), or another
# sample rate (`*_100hz`, `*_2khz`: the same 20 s, so 2 kHz is 4 x the
# samples), or noise (`noisy`); `two_hidden` has two effects that each hide
# the other (found by a trial round), `stribeck_theta` a Stribeck hump on the
# arm the equation error cannot see. Then `plantc identify` runs on it, and the
# script prints its wall and CPU time (user + sys), the effects it added,
# where it stopped, and whether the CPU time met the goal, with the machine's
# load average when the case ended (wall times mean little above the core
# count). The truth is in each case's truth.json. PLANTC=path/to/plantc
# skips the cargo build; PLANTC_THREADS=N sets the worker count.
# No peer runs here: bench/identify_vs_scipy.sh has the scipy pipeline side
# by side on the Coulomb case.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
if [ -z "${PLANTC:-}" ]; then
    cargo build --quiet --release -p plantc
    PLANTC="$target/release/plantc"
fi
dir="$target/bench-identify-cases"
mkdir -p "$dir"

# name | synth options (effects in SI, as `plantc synth --effect` takes them)
cases=(
    "none|"
    "viscous_alpha|--effect viscous_friction:alpha=3e-4"
    "drag_alpha|--effect quadratic_drag:alpha=2e-4"
    "coulomb_alpha|--effect coulomb_friction:alpha=6e-4"
    "stribeck_alpha|--effect stribeck_friction:alpha:Fc=4e-4,Fs=1.1e-3,vs=0.1"
    "spring_theta|--effect spring:theta=3e-3"
    "spring_alpha|--effect spring:alpha=2e-3"
    "input_delay|--effect input_delay:Vm=4e-3"
    "deadzone|--effect deadzone:Vm=0.4"
    "saturation|--effect saturation:Vm=1.5"
    "input_offset|--effect input_offset:Vm=0.3"
    "sensor_offset|--effect sensor_offset:alpha=0.03"
    "speed_limit|--effect speed_limit:theta:vmax=1.0,c=0.1"
    "added_inertia|--effect added_inertia:alpha=3e-4"
    "cogging|--effect cogging:theta:A=1e-2,N=24,phi=0.5"
    "two|--effect coulomb_friction:alpha=5e-4 --effect quadratic_drag:alpha=1.5e-4"
    "two_hidden|--effect spring:theta=2.5e-3 --effect coulomb_friction:alpha=5e-4"
    "stribeck_theta|--effect stribeck_friction:theta:Fc=4e-3,Fs=8e-3,vs=0.2"
    "coulomb_100hz|--effect coulomb_friction:alpha=6e-4 --rate 100"
    "coulomb_2khz|--effect coulomb_friction:alpha=6e-4 --rate 2000"
    "noisy|--effect coulomb_friction:alpha=6e-4 --noise 1e-3"
)

printf '%-16s %7s %7s %5s  %-5s %s\n' case "wall s" "CPU s" load "<=3s" "effects added; stop"
met=0
total=0
for entry in "${cases[@]}"; do
    name="${entry%%|*}"
    opts="${entry#*|}"
    if [ $# -gt 0 ] && ! printf '%s\n' "$@" | grep -qx "$name"; then
        continue
    fi
    # shellcheck disable=SC2086
    "$PLANTC" synth models/rotary_pendulum.plant $opts \
        --set J1=1.35e-3 --set l2=0.161 --set b1=2.9e-3 --set b2=6e-4 --set Fg1=0.013 \
        --experiment free_swing:alpha0=120deg,duration=20,name=free_swing_large \
        --experiment free_swing:alpha0=165deg,duration=20,name=free_swing_small \
        --experiment driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=3,duration=20 \
        --seed 1 --case "$name" -o "$dir/$name" --force >/dev/null
    /usr/bin/env time -f "%e %U %S" -o "$dir/$name.time" \
        "$PLANTC" identify models/rotary_pendulum.plant "$dir/$name"/*.csv \
        -o "$dir/$name-out" --force --json >"$dir/$name.json" 2>"$dir/$name.err" || {
        printf '%-16s failed: see %s\n' "$name" "$dir/$name.err"
        continue
    }
    read -r wall user sys <"$dir/$name.time"
    cpu=$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')
    ok=$(awk -v c="$cpu" 'BEGIN { print (c <= 3.0) ? "yes" : "no" }')
    total=$((total + 1))
    [ "$ok" = yes ] && met=$((met + 1))
    summary=$(python3 - "$dir/$name.json" <<'PY'
import json, sys
p = json.load(open(sys.argv[1]))
effects = [f"{r['effect']}@{r['target']}" for r in p.get("rounds", [])]
print(f"{', '.join(effects) if effects else 'none'}; {p.get('stop', '')}")
PY
)
    printf '%-16s %7.2f %7.2f %5s  %-5s %s\n' "$name" "$wall" "$cpu" \
        "$(cut -d' ' -f1 /proc/loadavg)" "$ok" "$summary"
done
echo "goal (issue 11): <= 3 s CPU per case: met in $met of $total"
