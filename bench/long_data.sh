#!/usr/bin/env bash
# Long records (reliability issue 12: a lab logging at 2 kHz for 10 minutes
# has 1.2e6 samples per channel). Makes a 1e6-sample driven experiment with
# `plantc synth` (2000 s at 500 Hz), then times `plantc compare` on it (target:
# under 2 s) beside a peer that only reads the same file (Python's csv module
# parsing every cell to float), prints the ratio and the peak memory; and, with
# `--fit`, `plantc fit` on it (target: under 60 s).
#
#   bash bench/long_data.sh [--fit] [SAMPLES]      # default 1000000
#
# The machine may be shared: CPU time (user + sys) is printed beside the wall
# time; load inflates only the latter.
set -euo pipefail
cd "$(dirname "$0")/.."
fit=0
if [ "${1:-}" = "--fit" ]; then fit=1; shift; fi
samples="${1:-1000000}"
duration=$(python3 -c "print($samples / 500)")
cargo build --quiet --release -p plantc
P=$PWD/target/release/plantc
M=$PWD/models/rotary_pendulum.plant
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
t() { /usr/bin/env time -f "%e s wall, %U s user + %S s sys, peak %M KB" "$@"; }

echo "== synth: driven experiment, $duration s at 500 Hz ($samples samples)"
t "$P" synth "$M" --experiment "driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=3,duration=$duration,name=long" \
    --rate 500 -o "$dir/data" > /dev/null
csv="$dir/data/long.csv"
echo "   $(wc -l < "$csv") lines, $(du -h "$csv" | cut -f1)"

echo "== plantc compare (read, simulate, fit %/RMSE, where it fails)"
out=$( { t "$P" compare "$M" "$csv" > /dev/null; } 2>&1 | tail -1)
echo "   $out"
cpu_plantc=$(echo "$out" | awk '{print $4 + $8}')

echo "== peer: Python csv module, reading and converting every cell only"
out=$( { t python3 -c '
import csv, sys
rows = 0
with open(sys.argv[1], newline="") as f:
    r = csv.reader(f); next(r)
    for row in r:
        [float(c) for c in row]; rows += 1
print(rows)' "$csv" > /dev/null; } 2>&1 | tail -1)
echo "   $out"
cpu_peer=$(echo "$out" | awk '{print $4 + $8}')
python3 -c "print(f'   CPU time plantc compare / Python read only: {$cpu_plantc / $cpu_peer:.2f}x; target compare < 2 s: {\"met\" if $cpu_plantc < 2 else \"NOT met\"} ({$cpu_plantc:.2f} s CPU)')"

if [ "$fit" = 1 ]; then
    echo "== plantc fit (5 estimate parameters; target < 60 s)"
    t "$P" fit "$M" "$csv" > /dev/null
fi
