#!/usr/bin/env bash
# Timing of the nominal fit (3 experiments x 10,000 samples, the 5 `estimate`
# parameters of the rotary pendulum), the equation-error ranking and a full
# diagnose on each shared case. The machine is shared: the script also prints
# the CPU time (user + sys) of the whole run, which load does not inflate.
#
#   bash bench/fit_timing.sh [DATA_DIR] [repeats]     (DATA_DIR default ../shared/data)
set -euo pipefail
cd "$(dirname "$0")/.."
data="${1:-../shared/data}"
repeats="${2:-3}"
if [ ! -d "$data" ]; then
    echo "no data folder $data" >&2
    exit 2
fi
cargo build --quiet --release -p plantc-identify --example fit_timing
for case in clean coulomb_pendulum spring_arm; do
    [ -d "$data/$case" ] || continue
    /usr/bin/env time -f "cpu_seconds %U user %S sys, wall %e s" \
        ./target/release/examples/fit_timing models/rotary_pendulum.plant "$data/$case" "$repeats"
done
