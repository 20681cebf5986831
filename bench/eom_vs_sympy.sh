#!/usr/bin/env bash
# Side-by-side timing: parse -> Euler-Lagrange equations -> linearization of the
# rotary pendulum, plantc versus SymPy's LagrangesMethod (same model, same
# parameter set `quanser_manual`). Creates a Python venv with SymPy on first use.
#
#   bash bench/eom_vs_sympy.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. bench/sympy_venv.sh
cargo build --quiet --release -p plantc-derive --example pipeline_timing
PLANTC=$(./target/release/examples/pipeline_timing models/rotary_pendulum.plant quanser_manual 200)
SYMPY=$("$VENV/bin/python" bench/eom_sympy.py)
"$VENV/bin/python" - "$PLANTC" "$SYMPY" <<'PY'
import json, sys
p = json.loads(sys.argv[1]); s = json.loads(sys.argv[2])
print(f"rotary pendulum: parse -> EOM -> linearize (set quanser_manual)")
print(f"  SymPy {s['sympy']:>8} LagrangesMethod: {s['seconds']*1e3:10.2f} ms   A[2][1] = {s['A21']:.6f}")
print(f"  plantc cold (first run, empty arena): {p['cold_s']*1e3:10.3f} ms   A[2][1] = {p['A21']:.6f}")
print(f"  plantc warm (median of {p['repeats']}):         {p['warm_median_s']*1e3:10.3f} ms")
print(f"  speed-up vs SymPy: {s['seconds']/p['cold_s']:.0f}x cold, {s['seconds']/p['warm_median_s']:.0f}x warm (goal: >= 100x)")
PY
