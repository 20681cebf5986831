//! Times plantc's parse -> Euler-Lagrange -> control-affine form -> Lie
//! derivatives -> normal form -> zero dynamics pipeline on a model file, and the
//! part shared with SymPy (parse -> EOM -> accelerations -> Lie derivatives).
//! Used by `bench/analysis_vs_sympy.sh`.
//!
//! Usage: `analysis_timing MODEL OUTPUT [SET] [REPEATS]`. Prints JSON with the
//! first (cold: empty expression arena) run and the median of the repeats.

use std::time::Instant;

use plantc_derive::analysis::{normal_form, zero_dynamics};
use plantc_derive::control::{output_expr, Derivation};
use plantc_derive::model::{load_model_text, ParameterValues};

/// Returns the relative degree and the largest |eigenvalue| of the zero dynamics.
fn pipeline(name: &str, text: &str, output: &str, set: Option<&str>, full: bool) -> (usize, f64) {
    let loaded = match load_model_text(name, text) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let model = &loaded.model;
    let values = ParameterValues::new(model, set, &[]).expect("parameter set");
    let d = Derivation::new(model).expect("equations");
    let h = output_expr(model, output).expect("output");
    let chain = d.lie_chain(model, h).expect("Lie derivatives");
    if !full {
        return (chain.relative_degree, 0.0);
    }
    let nf = normal_form(model, &d, &chain, &values, None).expect("normal form");
    let zd = zero_dynamics(model, &nf, &values).expect("zero dynamics");
    let m = zd.eigenvalues.iter().map(|p| p.abs()).fold(0.0, f64::max);
    (chain.relative_degree, m)
}

fn time(
    path: &str,
    text: &str,
    output: &str,
    set: Option<&str>,
    full: bool,
    repeats: usize,
) -> (f64, f64) {
    let t0 = Instant::now();
    std::hint::black_box(pipeline(path, text, output, set, full));
    let cold = t0.elapsed().as_secs_f64();
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        std::hint::black_box(pipeline(path, text, output, set, full));
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    (cold, times.get(times.len() / 2).copied().unwrap_or(cold))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map_or("models/rotary_pendulum.plant", String::as_str);
    let output = args.get(2).map_or("alpha", String::as_str);
    let set = args
        .get(3)
        .map(String::as_str)
        .filter(|s| !s.is_empty() && *s != "-");
    let repeats: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(200);
    let text = std::fs::read_to_string(path).expect("model file");
    // The full pipeline first, so that its cold time is a genuinely cold run.
    let (full_cold, full_warm) = time(path, &text, output, set, true, repeats);
    let (shared_cold, shared_warm) = time(path, &text, output, set, false, repeats);
    let (r, eig) = pipeline(path, &text, output, set, true);
    println!(
        "{{\"full_cold_s\": {full_cold:.6e}, \"full_warm_median_s\": {full_warm:.6e}, \
         \"shared_warm_median_s\": {shared_warm:.6e}, \"shared_after_full_s\": {shared_cold:.6e}, \
         \"repeats\": {repeats}, \"relative_degree\": {r}, \"zero_dynamics_max_abs_eig\": {eig}}}"
    );
}
