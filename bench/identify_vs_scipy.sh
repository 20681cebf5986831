#!/usr/bin/env bash
# A whole identification case, plantc against a scipy pipeline (issue 11,
# item 6: <= 3 s CPU per case, beside the scipy pipeline's 11-154 s of
# ../shared/reference/identification-notes.md).
#
#   bash bench/identify_vs_scipy.sh
#
# The case is made here by `plantc synth`, the kind of data/demo_coulomb: the
# rotary pendulum at values off nominal with a hidden dry (Coulomb) friction
# of 6e-4 N m on the pendulum; free_swing_large, free_swing_small and driven,
# 20 s at 500 Hz, 4096-count encoders (3 x 10,000 samples). Both tools start
# from models/rotary_pendulum.plant (5 `estimate` parameters) and the CSVs:
#
# - scipy: bench/scipy_identify.py, OUR OWN honest implementation of the
#   notes' pipeline (not the notes' code): equations of the model written by
#   hand in numpy and checked against `plantc derive --json`, solve_ivp with
#   the input held, least_squares (trf, bounds) nominal fit, equation-error
#   ranking of candidate effects on Savitzky-Golay derivatives,
#   simulation-error refits of the two leaders, verdict (one round). Each
#   phase is capped at PLANTC_BENCH_SCIPY_CAP s (default 300), said if hit.
# - plantc: `plantc identify` (nominal fit, diagnose, add, refit, in rounds
#   up to --max-effects, figures and report written).
#
# Prints each tool's wall and CPU time (user + sys of the process, which a
# loaded machine inflates less than wall), the ratio scipy / plantc, both
# verdicts, and plantc's CPU against the 3 s goal. A numpy+scipy venv is
# made on first use at PLANTC_BENCH_SCIPY_VENV (default
# ~/.cache/plantc-bench/venv-scipy); PLANTC=path/to/plantc skips the cargo
# build. Takes about 8 minutes (480 s measured, 2 cores, load 4.5), nearly
# all of it the scipy pipeline's simulation-error fits.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${PLANTC_BENCH_SCIPY_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/plantc-bench/venv-scipy}"
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet numpy scipy
fi
target="${CARGO_TARGET_DIR:-target}"
if [ -z "${PLANTC:-}" ]; then
    cargo build --quiet --release -p plantc
    PLANTC="$target/release/plantc"
fi
cap="${PLANTC_BENCH_SCIPY_CAP:-300}"
dir="$target/bench-identify-vs-scipy"
rm -rf "$dir"
mkdir -p "$dir"
"$PLANTC" synth models/rotary_pendulum.plant --case coulomb_alpha \
    --effect coulomb_friction:alpha=6e-4 \
    --set J1=1.35e-3 --set l2=0.161 --set b1=2.9e-3 --set b2=6e-4 --set Fg1=0.013 \
    --experiment free_swing:alpha0=120deg,duration=20,name=free_swing_large \
    --experiment free_swing:alpha0=165deg,duration=20,name=free_swing_small \
    --experiment driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=3,duration=20 \
    --seed 1 -o "$dir/case" >/dev/null
"$PLANTC" derive --json models/rotary_pendulum.plant >"$dir/derive.json"

echo "== scipy (bench/scipy_identify.py) =="
# one BLAS thread: deterministic sums, and CPU time comparable with plantc's
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
/usr/bin/env time -f "TIME %e %U %S" -o "$dir/scipy.time" \
    "$VENV/bin/python" bench/scipy_identify.py models/rotary_pendulum.plant "$dir/case" \
    --derive-json "$dir/derive.json" --cap "$cap" | tee "$dir/scipy.txt"

echo
echo "== plantc identify =="
/usr/bin/env time -f "TIME %e %U %S" -o "$dir/plantc.time" \
    "$PLANTC" identify models/rotary_pendulum.plant "$dir"/case/*.csv -o "$dir/plantc-out" --json \
    >"$dir/plantc.json" 2>"$dir/plantc.err"
echo "(story on stderr in $dir/plantc.err, summary in $dir/plantc.json)"

echo
"$VENV/bin/python" - "$dir" "$(cut -d' ' -f1 /proc/loadavg)" <<'PY'
import json, sys
d, load = sys.argv[1], sys.argv[2]
def times(f):
    line = [l for l in open(f) if l.startswith("TIME")][0].split()
    return float(line[1]), float(line[2]) + float(line[3])
sw, sc = times(f"{d}/scipy.time")
pw, pc = times(f"{d}/plantc.time")
s = json.loads([l for l in open(f"{d}/scipy.txt") if l.startswith("SUMMARY ")][0][8:])
p = json.load(open(f"{d}/plantc.json"))
effects = [f"{r['effect']} on {r['target']}" for r in p.get("rounds", [])]
stages = [(st["stage"], st["report"]["rmse"]) for st in p["stages"]]
params = p["fit"]["parameters"]
fc = params.get("Fc_alpha", {}).get("value")
print(f"case: rotary pendulum, hidden coulomb_friction on alpha = 6e-4 N m, 3 x 10,000 samples (load {load})")
print(f"{'':22}{'wall s':>10}{'CPU s':>10}   verdict")
print(f"{'scipy pipeline':22}{sw:>10.1f}{sc:>10.1f}   {s['verdict']}" + ("  (a phase hit its time cap)" if s["capped"] else ""))
print(f"{'plantc identify':22}{pw:>10.1f}{pc:>10.1f}   {', then '.join(effects) if effects else 'none'}"
      f" ({len(effects)} effect(s) added; {p.get('stop', '')})")
print(f"ratio scipy / plantc: {sw / pw:.1f}x wall, {sc / pc:.1f}x CPU")
print(f"RMSE (rad), scipy:  nominal {s['rmse_nominal']:.3e} -> refitted {s['rmse_refit']:.3e} -> with the effect {s['rmse_after']:.3e}")
print(f"RMSE (rad), plantc: " + " -> ".join(f"{n} {r:.3e}" for n, r in stages))
print(f"effect value (truth 6e-4 N m): scipy {s['effect_value'] if s['effect_value'] is not None else float('nan'):.4e}, "
      f"plantc Fc_alpha {fc if fc is not None else float('nan'):.4e}")
phases = ", ".join(f"{ph['name']} {ph['cpu']:.1f}" for ph in s["phases"] if ph["cpu"] >= 0.05)
print(f"scipy CPU by phase (s): {phases}")
print("(plantc also estimates sensor offsets, screens a second round and writes figures; the scipy peer does one round)")
print("reference, identification notes (their pipeline, other cases, same data size): 11-154 s per case,")
print("  nominal fit 9-63 s, equation-error ranking 0.25 s")
print(f"goal (issue 11): plantc identify <= 3 s CPU per case: {'met' if pc <= 3.0 else 'NOT met'} ({pc:.1f} s)")
PY
