//! A model file through check, rendering, loading, Euler-Lagrange and the
//! linearization of every parameter set: errors are fine, panics are bugs.
#![no_main]

use libfuzzer_sys::fuzz_target;
use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::control::Derivation;
use plantc_derive::lang::{parse_and_check, render, SourceFile};
use plantc_derive::model::{load_model_text, ParameterValues};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let checked = parse_and_check("fuzz.plant", text);
    let _ = render(&SourceFile::new("fuzz.plant", text), &checked.diagnostics);
    let Ok(loaded) = load_model_text("fuzz.plant", text) else {
        return;
    };
    // keep each input fast: the symbolic stages only for small models
    if text.len() > 8192 || loaded.model.coordinates.len() > 4 {
        return;
    }
    let model = &loaded.model;
    let Ok(derivation) = Derivation::new(model) else {
        return;
    };
    let mut sets: Vec<Option<&str>> = vec![None];
    sets.extend(model.sets.iter().map(|s| Some(s.name.as_str())));
    for s in sets {
        if let Ok(v) = ParameterValues::new(model, s, &[]) {
            let _ = linearize(
                model,
                &derivation.equations,
                &v,
                &OperatingPoint::zero(model),
            );
        }
    }
});
