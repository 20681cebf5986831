#!/usr/bin/env bash
# Robustness study of the rotary pendulum's balancing controllers (issue 14):
# pole placement, LQR, feedback linearization, fl_arm and sliding mode,
# designed with the thesis set, each against plants with J1, l2, b1 -/+20 %
# and with gearbox dry friction Fg1 = 0.01 N m added; from alpha = 10 deg,
# 10 s at 1 kHz. Prints the table (which hold, chattering = total variation
# of the voltage), then the wall and CPU time with 1 thread and with all
# cores (the cases run on scoped std threads; the machine may be shared, so
# compare the CPU time too).
#
#   bash bench/robustness.sh [extra plantc robustness arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --release -p plantc
args=(robustness models/rotary_pendulum.plant --set thesis
      --controller pole_placement --controller lqr_unit
      --controller feedback_linearization --controller fl_arm
      --controller sliding_mode
      --vary J1,l2,b1 --by 20% --add Fg1=0.01 --x0 alpha=10deg "$@")
./target/release/plantc "${args[@]}"
cores=$(nproc 2>/dev/null || echo 2)
for t in 1 "$cores"; do
    /usr/bin/env time -f "threads $t: wall %e s, cpu %U user + %S sys" \
        ./target/release/plantc "${args[@]}" --threads "$t" > /dev/null
done
