#!/usr/bin/env bash
# CasADi vs plantc generated code: ns per call of the rotary-pendulum dynamics,
# the feedback-linearizing law and one RK4 step (h = 1 ms), interleaved in one run.
#   bench/codegen_vs_casadi.sh            (uses $BENCH_DIR, default /tmp/plantc-bench-casadi)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
work="${BENCH_DIR:-/tmp/plantc-bench-casadi}"
mkdir -p "$work"
if [ ! -x "$work/venv/bin/python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install -q casadi
fi
"$work/venv/bin/python" "$here/codegen_vs_casadi.py" "$work"
gcc -O3 -march=native -fPIC -shared -o "$work/libcas.so" \
    "$work/cas.c" "$here/codegen_vs_casadi_wrap.c" -I"$work" -lm
cd "$root"
CARGO_TARGET_DIR="${BENCH_TARGET_DIR:-$work/target}" RUSTFLAGS="-C target-cpu=native" \
    cargo run --release -q -p rotpen-controller --example bench_casadi -- "$work/libcas.so"
