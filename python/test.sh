#!/usr/bin/env bash
# Builds the plantc wheel (maturin, dev profile), installs it into a fresh
# venv with pytest and numpy, and runs python/tests.
#
#   bash python/test.sh            # build + test
#   PLANTC_PY_RELEASE=1 bash python/test.sh   # release wheel
#
# Skips (exit 0, with a message) when python3, venv or pip is missing.
# Optional test dependencies (pandas, sympy, python-control) are installed
# only with PLANTC_PY_EXTRAS=1; their tests skip when absent. The CLI
# comparisons use target/{release,debug}/plantc (or PLANTC_BIN) when built.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
skip() { echo "python/test.sh: SKIPPED: $*"; exit 0; }

py="${PYTHON:-python3}"
command -v "$py" >/dev/null 2>&1 || skip "no $py on PATH"
"$py" -c 'import sys; assert sys.version_info >= (3, 9)' 2>/dev/null || skip "$py is older than 3.9"
"$py" -c 'import venv, ensurepip' 2>/dev/null || skip "$py has no venv/ensurepip (Debian: apt-get install python3-venv)"

work="${PLANTC_PY_WORK:-$root/target/python}"
mkdir -p "$work"
venv="$work/venv"
rm -rf "$venv"
"$py" -m venv "$venv" || skip "cannot create a venv"
pip=("$venv/bin/python" -m pip --disable-pip-version-check -q)
"${pip[@]}" install maturin pytest numpy || skip "pip cannot install maturin, pytest, numpy (offline?)"
if [ "${PLANTC_PY_EXTRAS:-0}" = 1 ]; then
    "${pip[@]}" install pandas sympy control || echo "python/test.sh: optional pandas/sympy/control not installed"
fi

start=$(date +%s)
profile=(--profile dev)
[ "${PLANTC_PY_RELEASE:-0}" = 1 ] && profile=(--release)
rm -rf "$work/wheels"
# the root's target directory: dependencies built by `cargo test` are reused
CARGO_TARGET_DIR="$root/target" PYO3_PYTHON="$venv/bin/python" \
    "$venv/bin/maturin" build -q "${profile[@]}" -m "$here/Cargo.toml" -i "$venv/bin/python" -o "$work/wheels"
built=$(date +%s)
echo "python/test.sh: wheel built in $((built - start)) s: $(ls "$work"/wheels/*.whl)"
"${pip[@]}" install --force-reinstall --no-deps "$work"/wheels/*.whl
# the command line the tests compare with (already built by `cargo test`)
if [ -z "${PLANTC_BIN:-}" ]; then
    (cd "$root" && cargo build -q -p plantc --bin plantc) && export PLANTC_BIN="$root/target/debug/plantc"
fi
cd "$work"   # never import the source tree's plantc/ by accident
"$venv/bin/python" -m pytest -q -p no:cacheprovider "$here/tests" "$@"
echo "python/test.sh: tests ran in $(( $(date +%s) - built )) s"
