#!/usr/bin/env bash
# The symbolic pipeline at scale: the n-link chain (plantc_derive::model::
# n_link_chain_source) through plantc and its peers, side by side.
#
#   bench/chain_scaling.sh              n = 2..10, 20, 30, 50 (SymPy up to 10)
#   NS="4 10" bench/chain_scaling.sh    chosen sizes
#   SYMPY_MAX=0 ...                     without SymPy (its derivation is slow)
#   CASADI_MAX=50 ...                   CasADi up to n = 50 (default 30: its
#                                       C code at n = 50 takes gcc -O3 very long)
#   PLANTC_DYNAMICS_FORM=closed ...     plantc's closed-form dynamics at every
#                                       size (or =recursive where separable):
#                                       the measurement of the size rule
#
# Per n it prints, as JSON lines and then tables:
# - plantc, each stage its own process, CPU time (user + sys), wall time and
#   peak RSS (GNU time): `analyze` = derive (equations + printed form),
#   linearize, analyze of the output q1 (Lie chain, normal form, zero
#   dynamics) in one process (derive/examples/scaling_timing.rs, which also
#   times each part); `derive` = `plantc derive` (its output's size);
#   `gen` = `plantc gen` (the generated crate's size); `rustc` = the generated
#   crate built in release (+ a small C-ABI shim) from a fresh target
#   directory, so every run compiles it for real;
# - peers (bench/chain_peers.py, a venv with sympy, casadi, mujoco and pin
#   from pip): SymPy derive (no simplify) + cse/C code, CasADi derive + C
#   code, MuJoCo's MJCF model; Pinocchio's ABA through its C++ API
#   (bench/chain_pinocchio.cpp, against the headers pip installed);
# - ns per forward-dynamics call (bench/chain_harness.c, gcc -O3
#   -march=native, Rust with -C target-cpu=native), interleaved rounds over
#   the same random states, on the thread's CPU time; and the agreement of
#   each peer with plantc (relative, inf-norm of the accelerations).
# Work files go to $BENCH_DIR (default /tmp/plantc-bench-chain).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
work="${BENCH_DIR:-/tmp/plantc-bench-chain}"
sizes="${NS:-2 3 4 5 6 7 8 9 10 20 30 50}"
mkdir -p "$work"
if [ ! -x "$work/venv/bin/python" ]; then
    python3 -m venv "$work/venv"
    "$work/venv/bin/pip" install -q sympy casadi
    "$work/venv/bin/pip" install -q mujoco || echo "mujoco did not install; continuing without it"
    "$work/venv/bin/pip" install -q pin || echo "pin (Pinocchio) did not install; continuing without it"
fi
py="$work/venv/bin/python"
site="$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
mj="$("$py" -c 'import mujoco, os; print(os.path.dirname(mujoco.__file__))' 2>/dev/null || true)"
# Pinocchio's C++ shim, built once (its headers are heavy)
pin_obj=""
if [ -d "$site/cmeel.prefix/include/pinocchio" ] && [ -d "$site/casadi/include/eigen3" ]; then
    pin_obj="$work/chain_pinocchio.o"
    if [ ! -f "$pin_obj" ] || [ "$here/chain_pinocchio.cpp" -nt "$pin_obj" ]; then
        g++ -O3 -march=native -DNDEBUG -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS \
            -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 \
            -I"$site/cmeel.prefix/include" -I"$site/casadi/include/eigen3" \
            -c "$here/chain_pinocchio.cpp" -o "$pin_obj" || pin_obj=""
    fi
fi
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && cargo build --release -q -p plantc -p plantc-derive \
    --bin plantc --example scaling_timing --example chain_model)
plantc="$target/release/plantc"
timing="$target/release/examples/scaling_timing"
# wall s, CPU s (user + sys), peak KB of a command into $1
tm() { /usr/bin/time -f '%e %U %S %M' -o "$1" "${@:2}"; }
results="$work/results.jsonl"
: >"$results"
for n in $sizes; do
    d="$work/n$n"
    rm -rf "$d/gen" "$d/target"
    mkdir -p "$d"
    "$target/release/examples/chain_model" "$n" >"$d/chain.plant"
    tm "$d/t_analyze" "$timing" "$d/chain.plant" q1 >"$d/plantc.json"
    tm "$d/t_derive" "$plantc" derive "$d/chain.plant" >"$d/derive.txt"
    tm "$d/t_gen" "$plantc" gen "$d/chain.plant" -o "$d/gen" --force >/dev/null
    nosym=""
    if [ "$n" -gt "${SYMPY_MAX:-10}" ]; then nosym="--no-sympy"; fi
    nocas=""
    if [ "$n" -gt "${CASADI_MAX:-30}" ]; then nocas="--no-casadi"; fi
    tm "$d/t_peers" "$py" "$here/chain_peers.py" "$d" "$n" $nosym $nocas >"$d/peers.json"
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
    # a fresh target directory: the crate is compiled for real every run
    tm "$d/t_rustc" env CARGO_TARGET_DIR="$d/target" RUSTFLAGS="-C target-cpu=native" \
        cargo build --release -q --manifest-path "$d/ffi/Cargo.toml"
    srcs=("$here/chain_harness.c")
    flags=(-DNL="$n")
    if [ -z "$nocas" ]; then
        srcs+=("$d/cas_chain.c" "$d/cas_wrap.c")
        flags+=(-DHAVE_CASADI)
    fi
    if [ -f "$d/sympy_chain.c" ] && [ -z "$nosym" ]; then
        srcs+=("$d/sympy_chain.c")
        flags+=(-DHAVE_SYMPY)
    fi
    libs=()
    if [ -n "$mj" ]; then
        flags+=(-DHAVE_MUJOCO -I"$mj/include")
        libs+=("$mj"/libmujoco.so.* -Wl,-rpath,"$mj")
    fi
    if [ -n "$pin_obj" ]; then
        flags+=(-DHAVE_PINOCCHIO)
        srcs+=("$pin_obj")
        libs+=(-L"$site/cmeel.prefix/lib" -lpinocchio_default -Wl,-rpath,"$site/cmeel.prefix/lib" -lstdc++)
    fi
    gcc -O3 -march=native -o "$d/harness" "${flags[@]}" -I"$d" "${srcs[@]}" \
        "$d/target/release/libchain_ffi.a" "${libs[@]}" -lm -lpthread -ldl
    "$d/harness" "$d/chain.xml" >"$d/speed.json"
    "$py" - "$d" >>"$results" <<'EOF'
import json, os, sys
d = sys.argv[1]
r = json.load(open(f"{d}/plantc.json"))
r.update(json.load(open(f"{d}/peers.json")))
r.update(json.load(open(f"{d}/speed.json")))
for k in ("analyze", "derive", "gen", "peers", "rustc"):
    wall, user, sys_, kb = open(f"{d}/t_{k}").read().split()[-4:]
    r[f"{k}_wall_s"], r[f"{k}_cpu_s"] = float(wall), float(user) + float(sys_)
    r[f"{k}_peak_mb"] = int(kb) / 1024
r["derive_bytes"] = os.path.getsize(f"{d}/derive.txt")
lib = open(f"{d}/gen/src/lib.rs").read()
r["gen_bytes"], r["gen_lines"] = len(lib.encode()), lib.count("\n")
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
print("plantc stages, CPU s (peak MB): analyze = derive (equations + printed form) + linearize + analyze q1 in one process;")
print("derive = `plantc derive` (output size); gen = `plantc gen` (lib.rs size); pipeline = analyze + gen; rustc = the generated crate, release")
print(f"{'n':>3} {'equations':>9} {'present':>8} {'lin':>7} {'analyze':>8} | {'analyze':>15} {'derive':>15} {'out KB':>8} {'gen':>15} {'lib.rs KB':>9} | {'pipeline':>8} {'peak MB':>7} | {'rustc':>15}")
for r in rows:
    an = r["lie_s"] + r["normal_form_s"] + r["zero_dynamics_s"]
    st = lambda k: f"{r[k + '_cpu_s']:7.2f} ({r[k + '_peak_mb']:5.0f})"
    total = r["analyze_cpu_s"] + r["gen_cpu_s"]
    peak = max(r["analyze_peak_mb"], r["gen_peak_mb"])
    print(f"{r['n']:>3} {r['equations_s']:9.3f} {r['present_s']:8.3f} {r['linearize_s']:7.4f} {an:8.3f} | {st('analyze')} {st('derive')} {r['derive_bytes'] / 1024:8.1f} {st('gen')} {r['gen_bytes'] / 1024:9.1f} | {total:8.2f} {peak:7.1f} | {st('rustc')}")
print()
print("peers, CPU s (peak MB of the peers' process): SymPy derive (no simplify) + cse/C code; CasADi derive + C code")
for r in rows:
    sy = r.get("sympy_derive_s")
    sy = None if sy is None else sy + r["sympy_codegen_s"]
    ca = r.get("casadi_derive_s")
    ca = None if ca is None else ca + r["casadi_codegen_s"]
    print(f"{r['n']:>3} sympy {f(sy, '{:8.2f}'):>8}  casadi {f(ca, '{:8.2f}'):>8}  ({r['peers_peak_mb']:.0f} MB)")
print()
peers = ("sympy", "casadi", "mujoco", "pinocchio")
print("forward dynamics, CPU ns per call (ratio = plantc / peer; <= 1: plantc faster), max relative difference to plantc")
print(f"{'n':>3} {'plantc':>8} " + " ".join(f"{p:>9}" for p in peers) + " | " + " ".join(f"{'/' + p:>10}" for p in peers) + f" {'/best':>6} | " + " ".join(f"{'err ' + p:>13}" for p in peers))
for r in rows:
    p = r["plantc_ns"]
    ns = {k: r.get(f"{k}_ns") for k in peers}
    best = min(v for v in ns.values() if v)
    print(f"{r['n']:>3} {p:8.1f} " + " ".join(f"{f(ns[k], '{:9.1f}'):>9}" for k in peers) + " | "
          + " ".join(f"{f(None if ns[k] is None else p / ns[k], '{:10.2f}'):>10}" for k in peers) + f" {p / best:6.2f} | "
          + " ".join(f"{f(r.get(k + '_rel_err'), '{:13.1e}'):>13}" for k in peers))
EOF
