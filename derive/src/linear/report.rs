//! JSON-serialisable result shapes for the command-line interface.

use serde::{Deserialize, Serialize};

use super::controllability::controllability;
use super::error::LinearError;
use super::linear_model::{matrix_to_rows, LinearModel};
use super::lqr::Lqr;
use super::place::Placement;
use super::poles::{poles, Pole};

/// Open-loop analysis: `{"poles": [{"re", "im"}], "controllable": bool, "controllability_rank": int}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnalysisReport {
    /// Eigenvalues of A, canonical order.
    pub poles: Vec<Pole>,
    /// Controllable by the PBH test on the balanced realisation.
    pub controllable: bool,
    /// Numerical rank of the controllability matrix (informative).
    pub controllability_rank: usize,
    /// PBH margin (see [`super::Controllability::pbh_margin`]).
    #[serde(default)]
    pub pbh_margin: f64,
}

/// Pole placement: `{"K": [[..]], "closed_loop_poles": [{"re", "im"}]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlaceReport {
    /// Gain rows (u = -K x).
    #[serde(rename = "K")]
    pub k: Vec<Vec<f64>>,
    /// Achieved closed-loop poles.
    pub closed_loop_poles: Vec<Pole>,
}

/// LQR: `{"K": [[..]], "P": [[..]], "closed_loop_poles": [..], "care_residual": x}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LqrReport {
    /// Gain rows (u = -K x).
    #[serde(rename = "K")]
    pub k: Vec<Vec<f64>>,
    /// Riccati solution rows.
    #[serde(rename = "P")]
    pub p: Vec<Vec<f64>>,
    /// Closed-loop poles.
    pub closed_loop_poles: Vec<Pole>,
    /// Relative CARE residual (see [`super::lqr::care_residual`]).
    pub care_residual: f64,
}

/// Poles and controllability of a model.
pub fn analyze(model: &LinearModel) -> Result<AnalysisReport, LinearError> {
    let ctrb = controllability(&model.a, &model.b)?;
    Ok(AnalysisReport {
        poles: poles(&model.a)?,
        controllable: ctrb.controllable,
        controllability_rank: ctrb.rank,
        pbh_margin: ctrb.pbh_margin,
    })
}

impl From<&Placement> for PlaceReport {
    fn from(p: &Placement) -> Self {
        PlaceReport {
            k: matrix_to_rows(&p.k),
            closed_loop_poles: p.closed_loop_poles.clone(),
        }
    }
}

impl From<&Lqr> for LqrReport {
    fn from(l: &Lqr) -> Self {
        LqrReport {
            k: matrix_to_rows(&l.k),
            p: matrix_to_rows(&l.p),
            closed_loop_poles: l.closed_loop_poles.clone(),
            care_residual: l.care_residual,
        }
    }
}

/// Pretty JSON of any report (serialising these plain structs cannot fail for
/// finite numbers; non-finite numbers become `null`).
pub fn to_json<T: Serialize>(report: &T) -> String {
    serde_json::to_string_pretty(report).unwrap_or_default()
}
