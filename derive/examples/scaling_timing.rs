//! Stage timings of the symbolic pipeline on one model file (used by
//! `bench/chain_scaling.sh`): parse, Euler-Lagrange, presentation of the
//! equations (`plantc derive`), linearization, and the analysis of an output
//! (Lie chain, normal form, zero dynamics). Prints one JSON object.
//!
//! Usage: `scaling_timing MODEL [OUTPUT]`.

use std::time::Instant;

use plantc_derive::analysis::{linearize, normal_form, zero_dynamics, OperatingPoint};
use plantc_derive::control::{output_expr, Derivation};
use plantc_derive::mechanics::{present_equations, Expand};
use plantc_derive::model::{load_model, ParameterValues};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(args.get(1).expect("model file"));
    let output = args.get(2).map(String::as_str);
    let t = Instant::now();
    let loaded = load_model(&path).unwrap_or_else(|e| {
        eprintln!("{}", e.render());
        std::process::exit(2)
    });
    let model = &loaded.model;
    let values = ParameterValues::new(model, None, &[]).expect("values");
    let parse = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let d = Derivation::new(model).expect("equations");
    let equations = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let p = present_equations(&d.equations, Expand::Auto);
    let present = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let lin =
        linearize(model, &d.equations, &values, &OperatingPoint::zero(model)).expect("linearize");
    let linearize_s = t.elapsed().as_secs_f64();
    let name = output
        .map(str::to_string)
        .unwrap_or_else(|| model.outputs[0].name.clone());
    let h = output_expr(model, &name).expect("output");
    let t = Instant::now();
    let chain = d.lie_chain(model, h).expect("Lie chain");
    let lie = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let nf = normal_form(model, &d, &chain, &values, None).expect("normal form");
    let nf_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let zd = zero_dynamics(model, &nf, &values).expect("zero dynamics");
    let zd_s = t.elapsed().as_secs_f64();
    println!(
        "{{\"n\": {}, \"parse_s\": {parse}, \"equations_s\": {equations}, \"present_s\": {present}, \
         \"linearize_s\": {linearize_s}, \"lie_s\": {lie}, \"normal_form_s\": {nf_s}, \
         \"zero_dynamics_s\": {zd_s}, \"notes\": {}, \"a10\": {}, \"zd_eigenvalues\": {}}}",
        model.coordinates.len(),
        p.notes.len(),
        lin.a[(lin.a.nrows() / 2, 0)],
        zd.eigenvalues.len()
    );
}
