//! ns per call: CasADi-generated C (loaded from a shared library) vs the
//! plantc-generated Rust, interleaved in one run. Run through
//! `bench/codegen_vs_casadi.sh` (release, `-C target-cpu=native`).
//!
//! The compared CasADi functions take the parameters and gains as an input
//! (live, set once at start), like plantc's generated `Plant` and controller,
//! which hold their parameter-only coefficients (computed once from
//! `Params`): both sides evaluate the same model with the same live values,
//! the gearbox dry friction's `sign` term included (its coefficient Fg1 is 0
//! in the thesis set, known to neither side when the functions were
//! generated). The `CasADi const` column is CasADi with the values compiled
//! in (Fg1 = 0 folds the sign term away), for reference only. The `free fn`
//! column calls `dynamics(x, u, &p)` / `rk4_step(x, u, &p, h)`, which
//! recompute the coefficients they need on every call. The run exits with
//! status 1 when plantc / CasADi (live parameters) is above [`TARGET`] for
//! any of the three functions.

use std::hint::black_box;
use std::time::Instant;

use rotpen_controller::rotary_pendulum::*;

type Dyn = unsafe extern "C" fn(*const f64, *const f64, *mut f64);
type Law = unsafe extern "C" fn(*const f64, *mut f64);
type SetParams = unsafe extern "C" fn(*const f64);

const NS: usize = 256;

/// The guarded ratio plantc / CasADi (live parameters) of each of the three
/// functions: issue 30's acceptance (`<= 0.7x`). The run exits with 1 when a
/// median is above it.
const TARGET: f64 = 0.7;
const REPS: usize = 20_000;

fn states() -> Vec<[f64; 4]> {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut r = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..NS)
        .map(|_| [r(), 0.5 * r(), 3.0 * r(), 3.0 * r()])
        .collect()
}

fn time(mut f: impl FnMut(&[f64; 4]) -> f64, xs: &[[f64; 4]]) -> f64 {
    let t = Instant::now();
    let mut acc = 0.0;
    for _ in 0..REPS / NS {
        for x in xs {
            acc += f(black_box(x));
        }
    }
    black_box(acc);
    t.elapsed().as_nanos() as f64 / ((REPS / NS) * NS) as f64
}

#[inline(never)]
fn p_dyn(x: &[f64; 4], u: &[f64; 1], plant: &Plant) -> [f64; 4] {
    plant.dynamics(x, u)
}
#[inline(never)]
fn p_dyn_free(x: &[f64; 4], u: &[f64; 1], p: &Params) -> [f64; 4] {
    dynamics(x, u, p)
}
#[inline(never)]
fn p_law(c: &FeedbackLinearization, x: &[f64; 4]) -> [f64; 1] {
    c.law(x)
}
#[inline(never)]
fn p_step(x: &[f64; 4], u: &[f64; 1], plant: &Plant) -> [f64; 4] {
    plant.rk4_step(x, u, 1e-3)
}
#[inline(never)]
fn p_step_free(x: &[f64; 4], u: &[f64; 1], p: &Params) -> [f64; 4] {
    rk4_step(x, u, p, 1e-3)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: bench_casadi LIBCAS.so");
    let lib = unsafe { libloading::Library::new(&path) }.expect("load the CasADi library");
    let c_dyn: libloading::Symbol<Dyn> = unsafe { lib.get(b"cas_dyn") }.unwrap();
    let c_law: libloading::Symbol<Law> = unsafe { lib.get(b"cas_law") }.unwrap();
    let c_step: libloading::Symbol<Dyn> = unsafe { lib.get(b"cas_step") }.unwrap();
    let k_dyn: libloading::Symbol<Dyn> = unsafe { lib.get(b"casc_dyn") }.unwrap();
    let k_law: libloading::Symbol<Law> = unsafe { lib.get(b"casc_law") }.unwrap();
    let k_step: libloading::Symbol<Dyn> = unsafe { lib.get(b"casc_step") }.unwrap();
    let set: libloading::Symbol<SetParams> = unsafe { lib.get(b"cas_set_params") }.unwrap();
    let (c_dyn, c_law, c_step) = (*c_dyn, *c_law, *c_step);
    let (k_dyn, k_law, k_step) = (*k_dyn, *k_law, *k_step);
    let p = Params::default();
    let plant = Plant::new(p);
    let ctrl = FeedbackLinearization::default();
    // the order of bench/codegen_vs_casadi.py's `names`
    let live = [
        p.m1,
        p.L1,
        p.l1,
        p.J1,
        p.b1,
        p.m2,
        p.l2,
        p.J2,
        p.b2,
        p.g,
        p.Kg,
        p.kt,
        p.km,
        p.eta_m,
        p.eta_g,
        p.Rm,
        p.Fg1,
        ctrl.wn(),
        ctrl.zeta(),
    ];
    unsafe { set(live.as_ptr()) };
    let xs = states();
    let u = [0.7];

    // agreement first
    let mut worst: f64 = 0.0;
    for x in &xs {
        let mut o = [0.0; 4];
        unsafe { c_dyn(x.as_ptr(), u.as_ptr(), o.as_mut_ptr()) };
        let d = dynamics(x, &u, &p);
        let mut l = [0.0];
        unsafe { c_law(x.as_ptr(), l.as_mut_ptr()) };
        let mut s = [0.0; 4];
        unsafe { c_step(x.as_ptr(), u.as_ptr(), s.as_mut_ptr()) };
        let (mut ko, mut kl, mut ks) = ([0.0; 4], [0.0], [0.0; 4]);
        unsafe { k_dyn(x.as_ptr(), u.as_ptr(), ko.as_mut_ptr()) };
        unsafe { k_law(x.as_ptr(), kl.as_mut_ptr()) };
        unsafe { k_step(x.as_ptr(), u.as_ptr(), ks.as_mut_ptr()) };
        let st = rk4_step(x, &u, &p, 1e-3);
        let (d2, st2) = (plant.dynamics(x, &u), plant.rk4_step(x, &u, 1e-3));
        for i in 0..4 {
            worst = worst.max((d2[i] - d[i]).abs() / (1.0 + d[i].abs()));
            worst = worst.max((st2[i] - st[i]).abs() / (1.0 + st[i].abs()));
            worst = worst.max((o[i] - d[i]).abs() / (1.0 + d[i].abs()));
            worst = worst.max((s[i] - st[i]).abs() / (1.0 + st[i].abs()));
            worst = worst.max((ko[i] - d[i]).abs() / (1.0 + d[i].abs()));
            worst = worst.max((ks[i] - st[i]).abs() / (1.0 + st[i].abs()));
        }
        let pl = ctrl.law(x)[0];
        worst = worst.max((l[0] - pl).abs() / (1.0 + pl.abs()));
        worst = worst.max((kl[0] - pl).abs() / (1.0 + pl.abs()));
    }
    println!("max relative difference CasADi vs plantc: {worst:.2e}");

    let rounds = 41;
    let mut t = vec![Vec::new(); 11];
    for _ in 0..rounds {
        t[0].push(time(
            |x| {
                let mut o = [0.0; 4];
                unsafe { c_dyn(x.as_ptr(), u.as_ptr(), o.as_mut_ptr()) };
                o[3]
            },
            &xs,
        ));
        t[1].push(time(|x| p_dyn(x, &u, &plant)[3], &xs));
        t[6].push(time(|x| p_dyn_free(x, &u, &p)[3], &xs));
        t[2].push(time(
            |x| {
                let mut o = [0.0];
                unsafe { c_law(x.as_ptr(), o.as_mut_ptr()) };
                o[0]
            },
            &xs,
        ));
        t[3].push(time(|x| p_law(&ctrl, x)[0], &xs));
        t[4].push(time(
            |x| {
                let mut o = [0.0; 4];
                unsafe { c_step(x.as_ptr(), u.as_ptr(), o.as_mut_ptr()) };
                o[3]
            },
            &xs,
        ));
        t[5].push(time(|x| p_step(x, &u, &plant)[3], &xs));
        t[7].push(time(|x| p_step_free(x, &u, &p)[3], &xs));
        t[8].push(time(
            |x| {
                let mut o = [0.0; 4];
                unsafe { k_dyn(x.as_ptr(), u.as_ptr(), o.as_mut_ptr()) };
                o[3]
            },
            &xs,
        ));
        t[9].push(time(
            |x| {
                let mut o = [0.0];
                unsafe { k_law(x.as_ptr(), o.as_mut_ptr()) };
                o[0]
            },
            &xs,
        ));
        t[10].push(time(
            |x| {
                let mut o = [0.0; 4];
                unsafe { k_step(x.as_ptr(), u.as_ptr(), o.as_mut_ptr()) };
                o[3]
            },
            &xs,
        ));
    }
    let m: Vec<f64> = t.into_iter().map(median).collect();
    println!(
        "{:<14} {:>10} {:>10} {:>16} {:>10} {:>14} {:>14} {:>14}",
        "ns/call",
        "CasADi",
        "plantc",
        "plantc/CasADi",
        "free fn",
        "free/CasADi",
        "CasADi const",
        "plantc/const"
    );
    let mut over = Vec::new();
    for (i, name) in ["dynamics", "FL law", "RK4 step"].iter().enumerate() {
        let (c, r) = (m[2 * i], m[2 * i + 1]);
        if r / c > TARGET {
            over.push(format!("{name} {:.2}", r / c));
        }
        let free = match i {
            0 => format!("{:>10.1} {:>14.2}", m[6], m[6] / c),
            2 => format!("{:>10.1} {:>14.2}", m[7], m[7] / c),
            _ => format!("{:>10} {:>14}", "-", "-"),
        };
        let k = m[8 + i];
        println!(
            "{name:<14} {c:>10.1} {r:>10.1} {:>16.2} {free} {k:>14.1} {:>14.2}",
            r / c,
            r / k
        );
    }
    if !over.is_empty() {
        eprintln!(
            "above the target of {TARGET}x CasADi with the same live parameters: {}",
            over.join(", ")
        );
        std::process::exit(1);
    }
    println!("dynamics, FL law and RK4 step each within {TARGET}x CasADi (same live parameters)");
}
