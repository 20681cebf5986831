//! `plantc stability`: exact interval of a gain line for which a
//! feedback-linearizing controller stabilises the origin.

use std::io::Write;
use std::path::Path;

use plantc_derive::analysis::stability_interval;
use plantc_derive::control::{resolve, Derivation};

use crate::cli::ParamArgs;
use crate::common::{load, num, values, write_json, CliError};

fn end(x: Option<f64>, inf: &str) -> String {
    x.map_or(inf.to_string(), num)
}

pub fn run(
    path: &Path,
    controller: &str,
    vary: &str,
    params: &ParamArgs,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(path, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, params)?;
    let gains: Vec<&str> = vary
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .collect();
    if gains.is_empty() {
        return Err(CliError::input(
            "error: --vary needs at least one gain, e.g. `--vary a,b`",
        ));
    }
    let d = Derivation::new(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let c = resolve(model, &d, controller, &vals)
        .map_err(|e| CliError::input(format!("error: {e}")))?;
    let s = stability_interval(model, &d, &c, &gains, &vals)
        .map_err(|e| CliError::input(format!("error: {e}")))?;
    for x in &s.disagreements {
        let _ = writeln!(
            err,
            "warning: at k = {x} the Routh-Hurwitz verdict and the closed-loop eigenvalues disagree"
        );
    }
    if json {
        let v = serde_json::json!({
            "controller": controller,
            "vary": s.gains,
            "intervals": s.intervals.iter().map(|(lo, hi)| serde_json::json!([lo, hi])).collect::<Vec<_>>(),
            "boundaries": s.boundaries,
            "char_poly": s.char_poly.iter().map(|p| &p.0).collect::<Vec<_>>(),
            "conditions": s.conditions.iter().map(|(n, p)| serde_json::json!({"name": n, "coefficients": p.0})).collect::<Vec<_>>(),
            "method": s.method,
        });
        write_json(out, &v);
        return Ok(());
    }
    let k = s.gains.join(" = ");
    let _ = writeln!(
        out,
        "controller {controller}, {k} = k: closed-loop linearization about the origin"
    );
    if s.intervals.is_empty() {
        let _ = writeln!(out, "  asymptotically stable for no k");
    }
    for (lo, hi) in &s.intervals {
        let _ = writeln!(
            out,
            "  asymptotically stable for {} < k < {}",
            end(*lo, "-inf"),
            end(*hi, "+inf")
        );
    }
    let b: Vec<String> = s.boundaries.iter().map(|x| format!("{x:.6}")).collect();
    let _ = writeln!(
        out,
        "  candidate boundaries (real roots of the conditions): {}",
        b.join(", ")
    );
    let _ = writeln!(out, "method: {}", s.method);
    Ok(())
}
