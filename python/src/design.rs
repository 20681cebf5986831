//! Linear state-feedback design and the command line's workflows.

use nalgebra::DMatrix;
use plantc_derive::linear::{lqr as solve_lqr, place as solve_place, LqrReport, PlaceReport, Pole};
use pyo3::prelude::*;

use crate::blocking;
use crate::errors::{compute, Failure};

/// A matrix from its rows; `what` names it in errors.
fn matrix(rows: &[Vec<f64>], what: &str) -> Result<DMatrix<f64>, Failure> {
    let r = rows.len();
    let c = rows.first().map_or(0, Vec::len);
    if rows.iter().any(|row| row.len() != c) {
        return Err(Failure::Input(format!("{what}: rows of different lengths")));
    }
    if let Some(x) = rows.iter().flatten().find(|x| !x.is_finite()) {
        return Err(Failure::Input(format!("{what}: entry {x} is not finite")));
    }
    Ok(DMatrix::from_fn(r, c, |i, j| rows[i][j]))
}

/// LQR `u = -K x` for `x' = A x + B u` and weights `Q`, `R`: the JSON of
/// `plantc lqr --json` (`K`, `P`, `closed_loop_poles`, `care_residual`).
#[pyfunction]
pub fn lqr(
    py: Python<'_>,
    a: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    q: Vec<Vec<f64>>,
    r: Vec<Vec<f64>>,
) -> PyResult<String> {
    blocking::run(py, move || {
        let l = solve_lqr(
            &matrix(&a, "A")?,
            &matrix(&b, "B")?,
            &matrix(&q, "Q")?,
            &matrix(&r, "R")?,
        )
        .map_err(compute)?;
        serde_json::to_string(&LqrReport::from(&l)).map_err(compute)
    })
}

/// Pole placement `u = -K x` (one input) for the poles `(re, im)`: the JSON
/// of `plantc place --json` (`K`, `closed_loop_poles`).
#[pyfunction]
pub fn place(
    py: Python<'_>,
    a: Vec<Vec<f64>>,
    b: Vec<Vec<f64>>,
    poles: Vec<(f64, f64)>,
) -> PyResult<String> {
    blocking::run(py, move || {
        let desired: Vec<Pole> = poles.iter().map(|&(re, im)| Pole { re, im }).collect();
        let p = solve_place(&matrix(&a, "A")?, &matrix(&b, "B")?, &desired).map_err(compute)?;
        serde_json::to_string(&PlaceReport::from(&p)).map_err(compute)
    })
}

/// Runs the command line in process with `args` (without the program
/// name): `(exit code, standard output, standard error)`. The Python half
/// calls the identification workflows with `--json` and reads the output.
#[pyfunction]
pub fn cli(py: Python<'_>, args: Vec<String>) -> PyResult<(i32, String, String)> {
    blocking::run(py, move || {
        let mut out = Vec::new();
        let mut err = Vec::new();
        let argv = std::iter::once("plantc".to_string()).chain(args);
        let code = plantc::run(argv, &mut out, &mut err);
        Ok((
            code,
            String::from_utf8_lossy(&out).into_owned(),
            String::from_utf8_lossy(&err).into_owned(),
        ))
    })
}
