//! `plantc place` and `plantc lqr`: linear state-feedback design.

use std::io::Write;

use nalgebra::DMatrix;
use plantc_derive::linear::{
    lqr as solve_lqr, parse_poles, place as solve_place, to_json, LinearModel, LqrReport,
    PlaceReport,
};

use super::linearize::{linearize_file, to_linear_model};
use crate::cli::LinearSource;
use crate::common::{complex_text, write_matrix, CliError};

fn linear_model(src: &LinearSource, err: &mut dyn Write) -> Result<LinearModel, CliError> {
    if let Some(path) = &src.linear {
        let text = std::fs::read_to_string(path).map_err(|e| {
            CliError::input(format!("error: cannot read `{}`: {e}", path.display()))
        })?;
        return LinearModel::from_json(&text)
            .map_err(|e| CliError::input(format!("error: {}: {e}", path.display())));
    }
    let path = src
        .model
        .as_ref()
        .ok_or_else(|| CliError::input("error: give a model file or --linear FILE.json"))?;
    let lin = linearize_file(path, &src.params, None, err)?;
    to_linear_model(&lin)
}

fn diag(text: &str, n: usize, what: &str) -> Result<DMatrix<f64>, CliError> {
    let v: Result<Vec<f64>, _> = text.split(',').map(|s| s.trim().parse::<f64>()).collect();
    let v = v.map_err(|_| {
        CliError::input(format!(
            "error: --{what} `{text}`: expected comma-separated numbers"
        ))
    })?;
    if v.len() != n {
        return Err(CliError::input(format!(
            "error: --{what} has {} entries, the system needs {n}",
            v.len()
        )));
    }
    Ok(DMatrix::from_diagonal(&nalgebra::DVector::from_vec(v)))
}

pub fn place(
    src: &LinearSource,
    poles: &str,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let lm = linear_model(src, err)?;
    let desired =
        parse_poles(poles).map_err(|e| CliError::input(format!("error: --poles: {e}")))?;
    let p = solve_place(&lm.a, &lm.b, &desired)
        .map_err(|e| CliError::failure(format!("error: {e}")))?;
    let report = PlaceReport::from(&p);
    if json {
        let _ = writeln!(out, "{}", to_json(&report));
        return Ok(());
    }
    write_matrix(out, "K (u = -K x)", &report.k, &lm.inputs);
    let _ = writeln!(out, "  columns: {}", lm.state.join(", "));
    let cl: Vec<String> = report
        .closed_loop_poles
        .iter()
        .map(|p| complex_text(p.re, p.im))
        .collect();
    let _ = writeln!(out, "closed-loop poles: {}", cl.join(", "));
    Ok(())
}

pub fn lqr(
    src: &LinearSource,
    q: &str,
    r: &str,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let lm = linear_model(src, err)?;
    let qm = diag(q, lm.n_states(), "q")?;
    let rm = diag(r, lm.n_inputs(), "r")?;
    let l =
        solve_lqr(&lm.a, &lm.b, &qm, &rm).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let report = LqrReport::from(&l);
    if json {
        let _ = writeln!(out, "{}", to_json(&report));
        return Ok(());
    }
    write_matrix(out, "K (u = -K x)", &report.k, &lm.inputs);
    let _ = writeln!(out, "  columns: {}", lm.state.join(", "));
    write_matrix(out, "P", &report.p, &lm.state);
    let cl: Vec<String> = report
        .closed_loop_poles
        .iter()
        .map(|p| complex_text(p.re, p.im))
        .collect();
    let _ = writeln!(out, "closed-loop poles: {}", cl.join(", "));
    let _ = writeln!(
        out,
        "CARE residual (relative): {:.3e}",
        report.care_residual
    );
    Ok(())
}
