#!/usr/bin/env bash
# Side-by-side timing: parse -> Euler-Lagrange -> Lie derivatives -> normal form
# -> zero dynamics of the rotary pendulum with output alpha (plantc), beside
# SymPy doing the steps it can (LagrangesMethod EOM, accelerations, Lie
# derivatives of h = alpha). Reuses the venv of bench/eom_vs_sympy.sh.
#
#   bash bench/analysis_vs_sympy.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. bench/sympy_venv.sh
cargo build --quiet --release -p plantc-derive --example analysis_timing
PLANTC=$(./target/release/examples/analysis_timing models/rotary_pendulum.plant alpha thesis 200)
SYMPY=$("$VENV/bin/python" bench/analysis_sympy.py)
"$VENV/bin/python" - "$PLANTC" "$SYMPY" <<'PY'
import json, sys
p = json.loads(sys.argv[1]); s = json.loads(sys.argv[2])
ms = lambda x: f"{x*1e3:10.3f} ms"
print("rotary pendulum, output alpha (set thesis)")
print(f"  SymPy {s['sympy']}: EOM {ms(s['eom_s'])}, accelerations {ms(s['accelerations_s'])}, Lie derivatives {ms(s['lie_s'])}")
print(f"  SymPy shared steps (EOM -> accelerations -> Lie):  {ms(s['shared_s'])}   L_g h == 0: {s['Lgh_is_zero']}")
print(f"  SymPy + simplify(L_g L_f h):                        {ms(s['shared_s'] + s['simplify_LgLfh_s'])}")
print(f"  plantc shared steps, warm median:                   {ms(p['shared_warm_median_s'])}")
print(f"  plantc full pipeline (+ normal form, zero dynamics): cold {ms(p['full_cold_s'])}, warm median {ms(p['full_warm_median_s'])}")
print(f"  speed-up on the shared steps: {s['shared_s']/p['shared_warm_median_s']:.0f}x warm, "
      f"{s['shared_s']/p['full_cold_s']:.0f}x (SymPy shared vs plantc full pipeline cold) (goal >= 100x)")
print(f"  full pipeline under 10 ms: cold {'yes' if p['full_cold_s'] < 0.01 else 'NO'}, warm {'yes' if p['full_warm_median_s'] < 0.01 else 'NO'}")
PY
