# Sourced by the bench scripts: a Python venv with SymPy, made on first use.
# Sets VENV. Override the location with PLANTC_BENCH_VENV.
VENV="${PLANTC_BENCH_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/plantc-bench/venv}"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet sympy
fi
