//! Times plantc's parse -> Euler-Lagrange -> linearize pipeline on a model file.
//! Used by `bench/eom_vs_sympy.sh`, which runs SymPy's LagrangesMethod on the
//! same model beside it.
//!
//! Usage: `pipeline_timing MODEL [SET] [REPEATS]`. Prints JSON with the time of
//! the first (cold: empty expression arena) run and the median of the repeats.

use std::time::Instant;

use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::mechanics::derive_equations;
use plantc_derive::model::{load_model_text, ParameterValues};

fn pipeline(name: &str, text: &str, set: Option<&str>) -> f64 {
    let loaded = match load_model_text(name, text) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let model = &loaded.model;
    let values = ParameterValues::new(model, set, &[]).expect("parameter set");
    let eqs = derive_equations(model).expect("equations");
    let lin = linearize(model, &eqs, &values, &OperatingPoint::zero(model)).expect("linearization");
    lin.a[(2, 1)]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map_or("models/rotary_pendulum.plant", String::as_str);
    let set = args
        .get(2)
        .map(String::as_str)
        .filter(|s| !s.is_empty() && *s != "-");
    let repeats: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(200);
    let text = std::fs::read_to_string(path).expect("model file");
    let t0 = Instant::now();
    let a21 = pipeline(path, &text, set);
    let cold = t0.elapsed().as_secs_f64();
    let mut times = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        std::hint::black_box(pipeline(path, &text, set));
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(cold);
    println!(
        "{{\"cold_s\": {cold:.6e}, \"warm_median_s\": {median:.6e}, \"repeats\": {repeats}, \"A21\": {a21}}}"
    );
}
