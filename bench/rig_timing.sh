#!/usr/bin/env bash
# Controller + velocity observer time per loop cycle: the generated rig binary
# (`plantc gen --rig`) next to the interpreted path (`plantc run`), same run
# settings (simulator, 30 s from 5 deg, seeded noise), both release builds.
# Prints each path's p50/p99 of "estimator + controller" from the run reports
# and the ratio, plus the rig crate's release build time (from scratch, in
# its own target directory) and binary size.
#   bench/rig_timing.sh            (work dir $BENCH_DIR, default /tmp/plantc-bench-rig)
# The figures come from the loop's own timer (std::time::Instant around each
# call), whose resolution and overhead (tens of ns) dominate the generated path.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
work="${BENCH_DIR:-/tmp/plantc-bench-rig}"
cd "$root"
cargo build --release -q -p plantc
plantc="$root/target/release/plantc"
rm -rf "$work"
mkdir -p "$work"
"$plantc" gen models/rotary_pendulum.plant --set thesis \
    --controller pole_placement --controller fl_arm --rig -o "$work/rig" > /dev/null
start=$(date +%s.%N)
(cd "$work/rig" && CARGO_TARGET_DIR="$work/target" cargo build --release -q)
end=$(date +%s.%N)
bin="$work/target/release/rotary-pendulum-rig"
printf 'rig crate release build from scratch: %.1f s; binary %s bytes\n' \
    "$(echo "$end - $start" | bc)" "$(stat -c %s "$bin")"
args=(--x0 alpha=5deg --duration 30 --sim-noise counts=0.5,volts=0.05,seed=7)
field() { sed -n "s/.*estimator + controller: p50 \([0-9]*\) ns, p99 \([0-9]*\) ns.*/\1 \2/p"; }
for c in pole_placement fl_arm; do
    for rep in 1 2 3; do
        read -r gp50 gp99 < <("$bin" --controller "$c" "${args[@]}" 2>/dev/null | field)
        read -r ip50 ip99 < <("$plantc" run models/rotary_pendulum.plant --set thesis \
            --controller "$c" "${args[@]}" 2>/dev/null | field)
        printf '%-15s run %d: generated p50 %4d ns (p99 %4d), interpreted p50 %4d ns (p99 %4d): %.1fx\n' \
            "$c" "$rep" "$gp50" "$gp99" "$ip50" "$ip99" "$(echo "$ip50 / $gp50" | bc -l)"
    done
done
