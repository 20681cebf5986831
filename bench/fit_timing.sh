#!/usr/bin/env bash
# Timing of the nominal fit (3 experiments x 10,000 samples, the 5 `estimate`
# parameters of the rotary pendulum), the equation-error ranking and a full
# diagnose on each case folder (free_swing_large.csv, free_swing_small.csv,
# driven.csv). The machine may be shared: the script also prints the CPU time
# (user + sys) of each run, which load does not inflate.
#
#   bash bench/fit_timing.sh [DATA_DIR] [repeats]
#
# DATA_DIR is a case folder or a folder of case folders; default `data` (the
# bundled recordings, e.g. data/demo_coulomb). Any recordings in the same
# layout work, e.g. folders written by `plantc synth`.
set -euo pipefail
cd "$(dirname "$0")/.."
data="${1:-data}"
repeats="${2:-3}"
if [ ! -d "$data" ]; then
    echo "no data folder $data" >&2
    exit 2
fi
cargo build --quiet --release -p plantc-identify --example fit_timing
cases=()
if [ -f "$data/driven.csv" ]; then
    cases=("$data")
else
    for d in "$data"/*/; do
        [ -f "$d/driven.csv" ] && cases+=("${d%/}")
    done
fi
if [ ${#cases[@]} -eq 0 ]; then
    echo "no case folder (with driven.csv) in $data" >&2
    exit 2
fi
for case in "${cases[@]}"; do
    /usr/bin/env time -f "cpu_seconds %U user %S sys, wall %e s" \
        ./target/release/examples/fit_timing models/rotary_pendulum.plant "$case" "$repeats"
done
