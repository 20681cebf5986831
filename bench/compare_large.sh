#!/usr/bin/env bash
# `plantc compare` on a very long record (reliability issue 31: "1e7 rows
# stay under 1 GB and a few minutes"). Builds the record from bundled data
# only: the demo's driven experiment (data/demo_coulomb/driven.csv, 10000
# rows, 20 s at 500 Hz) tiled end to end, each copy's times shifted by the
# record's length (20 s) so time stays strictly increasing and evenly
# sampled; then runs `plantc compare` on it under `/usr/bin/time -v` and
# prints the rows, CPU time, wall time and peak resident memory.
#
#   bash bench/compare_large.sh [ROWS]        # default 10000000
#
# Exits 1 when the peak RSS is 1 GB (1e9 bytes) or more, the issue's bound.
# Not part of CI: the 1e7-row file is ~0.4 GB and compare takes minutes.
# The machine may be shared: CPU time (user + sys) is printed beside the wall
# time; load inflates only the latter (the load average is printed too).
set -euo pipefail
cd "$(dirname "$0")/.."
rows="${1:-10000000}"
src=data/demo_coulomb/driven.csv
cargo build --quiet --release -p plantc
P=$PWD/target/release/plantc
M=$PWD/models/rotary_pendulum.plant
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
csv="$dir/long.csv"

# one tile: the source's data rows; its period is its row count times its
# sample time (read from the first two rows)
awk -F, -v rows="$rows" '
    NR == 1 { print; next }
    { t[NR - 1] = $1; rest[NR - 1] = substr($0, length($1) + 1) }
    END {
        n = NR - 1
        period = n * (t[2] - t[1])
        for (k = 0; k < rows; k++) {
            i = k % n + 1
            printf "%.4f%s\n", t[i] + int(k / n) * period, rest[i]
        }
    }' "$src" > "$csv"
n=$(($(wc -l < "$csv") - 1))
echo "== record: $n rows ($(du -h "$csv" | cut -f1)), $src tiled"

echo "== plantc compare (load average before: $(cut -d' ' -f1-3 /proc/loadavg))"
/usr/bin/time -v "$P" compare "$M" "$csv" > "$dir/out.txt" 2> "$dir/time.txt" || {
    echo "compare failed:"; cat "$dir/out.txt" "$dir/time.txt"; exit 2; }
sed -n '1,6p' "$dir/out.txt" | sed 's/^/   /'
field() { grep -F "$1" "$dir/time.txt" | head -1 | awk -F': ' '{print $2}'; }
user=$(field "User time (seconds)")
sys=$(field "System time (seconds)")
wall=$(field "Elapsed (wall clock) time")
kb=$(field "Maximum resident set size (kbytes)")
python3 - "$n" "$user" "$sys" "$wall" "$kb" <<'PY'
import sys
n, user, sys_, wall, kb = sys.argv[1:]
parts = [float(x) for x in wall.split(":")]
secs = sum(v * 60 ** i for i, v in enumerate(reversed(parts)))
mb = int(kb) * 1024 / 1e6
print(f"rows {n}  CPU {float(user) + float(sys_):.1f} s (user {user} + sys {sys_})  "
      f"wall {secs:.1f} s  peak RSS {mb:.0f} MB")
ok = mb < 1000
print(f"peak RSS < 1 GB: {'met' if ok else 'NOT met'}")
sys.exit(0 if ok else 1)
PY
