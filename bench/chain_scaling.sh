#!/usr/bin/env bash
# The symbolic pipeline at scale: the n-link chain (plantc_derive::model::
# n_link_chain_source) through plantc and its peers, side by side.
#
#   bench/chain_scaling.sh              n = 2 4 6 8 10 20 (SymPy up to 10)
#   NS="4 10" bench/chain_scaling.sh    chosen sizes
#
# Per n it prints, as JSON lines and then a table:
# - plantc: derive (Euler-Lagrange + printed M, bias, Q, B), linearize,
#   analyze (output q1: Lie chain, normal form, zero dynamics) in one process
#   (derive/examples/scaling_timing.rs), and `plantc gen`; wall time and peak
#   RSS of each process (GNU time);
# - peers (bench/chain_peers.py, a venv with sympy, casadi, mujoco from pip):
#   SymPy derive (no simplify) + cse/C code, CasADi derive + C code;
# - ns per forward-dynamics call (bench/chain_harness.c, gcc -O3
#   -march=native, Rust with -C target-cpu=native), interleaved, and the
#   agreement of each peer with plantc (relative, inf-norm of accelerations).
# Work files go to $BENCH_DIR (default /tmp/plantc-bench-chain).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
work="${BENCH_DIR:-/tmp/plantc-bench-chain}"
sizes="${NS:-2 4 6 8 10 20}"
mkdir -p "$work"
if [ ! -x "$work/venv/bin/python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install -q sympy casadi
    "$work/venv/bin/pip" install -q mujoco || echo "mujoco did not install; continuing without it"
fi
py="$work/venv/bin/python"
mj="$("$py" -c 'import mujoco, os; print(os.path.dirname(mujoco.__file__))' 2>/dev/null || true)"
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && cargo build --release -q -p plantc -p plantc-derive \
    --bin plantc --example scaling_timing --example chain_model)
plantc="$target/release/plantc"
timing="$target/release/examples/scaling_timing"
tm() { /usr/bin/time -f '%e %M' -o "$1" "${@:2}"; }
results="$work/results.jsonl"
: >"$results"
for n in $sizes; do
    d="$work/n$n"
    mkdir -p "$d"
    "$target/release/examples/chain_model" "$n" >"$d/chain.plant"
    tm "$d/t_analyze" "$timing" "$d/chain.plant" q1 >"$d/plantc.json"
    tm "$d/t_gen" "$plantc" gen "$d/chain.plant" -o "$d/gen" --force >/dev/null
    nosym=""
    if [ "$n" -gt 10 ]; then nosym="--no-sympy"; fi
    tm "$d/t_peers" "$py" "$here/chain_peers.py" "$d" "$n" $nosym >"$d/peers.json"
    # the plantc-generated crate behind a C ABI
    mkdir -p "$d/ffi/src"
    cat >"$d/ffi/Cargo.toml" <<EOF
[package]
name = "chain_ffi"
version = "0.1.0"
edition = "2021"
publish = false
[workspace]
[lib]
crate-type = ["staticlib"]
[dependencies]
chain$n = { path = "../gen" }
[profile.release]
codegen-units = 1
EOF
    cat >"$d/ffi/src/lib.rs" <<EOF
use chain$n::{Plant, N_INPUTS, N_STATES};
#[no_mangle]
pub extern "C" fn plantc_chain_new() -> *mut Plant {
    Box::into_raw(Box::new(Plant::default()))
}
/// # Safety
/// Pointers from plantc_chain_new and to N_STATES / N_INPUTS / N_STATES doubles.
#[no_mangle]
pub unsafe extern "C" fn plantc_chain_dyn(p: *const Plant, x: *const f64, u: *const f64, out: *mut f64) {
    let x = &*(x as *const [f64; N_STATES]);
    let u = &*(u as *const [f64; N_INPUTS]);
    *(out as *mut [f64; N_STATES]) = (*p).dynamics(x, u);
}
EOF
    tm "$d/t_rustc" env CARGO_TARGET_DIR="$work/target" RUSTFLAGS="-C target-cpu=native" \
        cargo build --release -q --manifest-path "$d/ffi/Cargo.toml"
    srcs=("$here/chain_harness.c" "$d/cas_chain.c" "$d/cas_wrap.c")
    flags=(-DNL="$n")
    if [ -f "$d/sympy_chain.c" ] && [ -z "$nosym" ]; then
        srcs+=("$d/sympy_chain.c")
        flags+=(-DHAVE_SYMPY)
    fi
    if [ -n "$mj" ]; then
        flags+=(-DHAVE_MUJOCO -I"$mj/include")
        libs=("$mj"/libmujoco.so.* -Wl,-rpath,"$mj")
    else
        libs=()
    fi
    gcc -O3 -march=native -o "$d/harness" "${flags[@]}" -I"$d" "${srcs[@]}" \
        "$work/target/release/libchain_ffi.a" "${libs[@]}" -lm -lpthread -ldl
    "$d/harness" "$d/chain.xml" >"$d/speed.json"
    "$py" - "$d" >>"$results" <<'EOF'
import json, sys
d = sys.argv[1]
r = json.load(open(f"{d}/plantc.json"))
r.update(json.load(open(f"{d}/peers.json")))
r.update(json.load(open(f"{d}/speed.json")))
for k in ("analyze", "gen", "peers", "rustc"):
    s, kb = open(f"{d}/t_{k}").read().split()[-2:]
    r[f"{k}_wall_s"], r[f"{k}_peak_mb"] = float(s), int(kb) / 1024
print(json.dumps(r))
EOF
    tail -1 "$results"
done
"$py" - "$results" <<'EOF'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
def f(x, fmt="{:.3f}"):
    return "-" if x is None else fmt.format(x)
print()
print("plantc (s): derive = equations + printed form; analyze = Lie chain + normal form + zero dynamics (output q1)")
print(f"{'n':>3} {'derive':>7} {'lin':>7} {'analyze':>7} {'gen':>6} {'total':>6} {'peakMB':>7} | {'sympy der+cg':>12} {'casadi der+cg':>13} {'peersMB':>7}")
for r in rows:
    der = r["equations_s"] + r["present_s"]
    an = r["lie_s"] + r["normal_form_s"] + r["zero_dynamics_s"]
    total = r["analyze_wall_s"] + r["gen_wall_s"]
    peak = max(r["analyze_peak_mb"], r["gen_peak_mb"])
    sy = r.get("sympy_derive_s")
    sy = None if sy is None else sy + r["sympy_codegen_s"]
    ca = r["casadi_derive_s"] + r["casadi_codegen_s"]
    print(f"{r['n']:>3} {der:7.3f} {r['linearize_s']:7.4f} {an:7.3f} {r['gen_wall_s']:6.2f} {total:6.2f} {peak:7.1f} | {f(sy, '{:12.2f}'):>12} {ca:13.2f} {r['peers_peak_mb']:7.1f}")
print()
print("generated forward dynamics, ns per call (ratio = plantc / peer; <= 1 is plantc faster), max relative difference to plantc")
print(f"{'n':>3} {'plantc':>8} {'sympy':>8} {'casadi':>8} {'mujoco':>8} | {'/sympy':>6} {'/casadi':>7} {'/mujoco':>7} {'/best':>6} | {'err sympy':>9} {'err casadi':>10} {'err mujoco':>10} {'casadi-sympy':>12}")
for r in rows:
    p = r["plantc_ns"]
    peers = {k: r.get(f"{k}_ns") for k in ("sympy", "casadi", "mujoco")}
    best = min(v for v in peers.values() if v)
    rat = {k: (None if v is None else p / v) for k, v in peers.items()}
    print(f"{r['n']:>3} {p:8.1f} {f(peers['sympy'], '{:8.1f}'):>8} {f(peers['casadi'], '{:8.1f}'):>8} {f(peers['mujoco'], '{:8.1f}'):>8} | "
          f"{f(rat['sympy'], '{:6.2f}'):>6} {f(rat['casadi'], '{:7.2f}'):>7} {f(rat['mujoco'], '{:7.2f}'):>7} {p / best:6.2f} | "
          f"{f(r.get('sympy_rel_err'), '{:9.1e}'):>9} {f(r.get('casadi_rel_err'), '{:10.1e}'):>10} {f(r.get('mujoco_rel_err'), '{:10.1e}'):>10} {f(r.get('casadi_vs_sympy_rel_err'), '{:12.1e}'):>12}")
EOF
