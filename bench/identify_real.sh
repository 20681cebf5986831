#!/usr/bin/env bash
# Identification on the real recordings (issue 27's real-data bench): the
# QUBE episodes (closed loop, models/qube_servo.plant) and the DFKI double
# pendulum (models/double_pendulum.plant with the viscous-only friction of
# identify/tests/real_dfki.rs, whose diagnosis must find the Coulomb
# friction). Prints wall and CPU (user + sys) per case, the machine's load
# and the verdict. The recordings are third-party and not bundled: read from
# ../shared/data/real (cases whose data are absent are skipped with a note).
#
#   bash bench/identify_real.sh                 # every case
#   bash bench/identify_real.sh qube3 dfki      # some of them, by name
#   PLANTC_THREADS=1 bash bench/identify_real.sh  # one worker
#
# PLANTC=path/to/plantc skips the cargo build.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
if [ -z "${PLANTC:-}" ]; then
    cargo build --quiet --release -p plantc
    PLANTC="$target/release/plantc"
fi
real=../shared/data/real
dir="$target/bench-identify-real"
mkdir -p "$dir"

want() { [ $# -eq 0 ] || printf '%s\n' "${@}" | grep -qx "$which"; }

run() { # name model files...
    local name="$1" model="$2"
    shift 2
    /usr/bin/env time -f "%e %U %S" -o "$dir/$name.time" \
        "$PLANTC" identify "$model" "$@" -o "$dir/$name-out" --force --json \
        >"$dir/$name.json" 2>"$dir/$name.err" || {
        printf '%-8s failed: see %s\n' "$name" "$dir/$name.err"
        return
    }
    read -r wall user sys <"$dir/$name.time"
    cpu=$(awk -v u="$user" -v s="$sys" 'BEGIN { printf "%.2f", u + s }')
    verdict=$(grep -o '"verdict": "[^"]*"' "$dir/$name.json" | head -1 | cut -d'"' -f4)
    printf '%-8s %7s %7s  %5s  %s\n' "$name" "$wall" "$cpu" \
        "$(cut -d' ' -f1 /proc/loadavg)" "$verdict"
}

printf '%-8s %7s %7s  %5s  %s\n' case "wall s" "CPU s" load verdict
qube="$real/qube_koopman_prbs/raw"
which=qube3
if want "$@"; then
    if ls "$qube"/*.csv >/dev/null 2>&1; then
        # shellcheck disable=SC2046
        run qube3 models/qube_servo.plant $(ls "$qube"/*.csv | sort | head -3) --map Vm=plant_input
    else
        echo "qube3    skipped: $qube not present"
    fi
fi
which=qube16
if want "$@"; then
    many="$real/qube_koopman_prbs/more"
    if ls "$many"/*.csv >/dev/null 2>&1; then
        # the 3 raw episodes and the 13 more of the same session
        # shellcheck disable=SC2046
        run qube16 models/qube_servo.plant $(ls "$qube"/*.csv "$many"/*.csv | sort) --map Vm=plant_input
    else
        echo "qube16   skipped: $many not present"
    fi
fi
which=dfki
if want "$@"; then
    traj="$real/dfki_double_pendulum_sysid/converted/trajectory_00.csv"
    if [ -f "$traj" ]; then
        # the model without its Coulomb friction (identify/tests/real_dfki.rs)
        grep -v '^parameter Fc' models/double_pendulum.plant |
            sed -e 's/ + coulomb_friction(Fc1)//' -e 's/ + coulomb_friction(Fc2)//' \
                >"$dir/double_pendulum_viscous.plant"
        run dfki "$dir/double_pendulum_viscous.plant" "$traj" \
            --map tau1=tau1_meas --map tau2=tau2_meas
    else
        echo "dfki     skipped: $traj not present"
    fi
fi
