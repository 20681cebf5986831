//! What the newer controller designs of a model file mean: sliding surfaces,
//! and the modes and switch conditions of hybrid controllers.

use crate::lang::ast::CmpOp;
use crate::sym::Expr;

/// How a sliding surface `s(x)` is given.
#[derive(Clone, Debug, PartialEq)]
pub enum SurfaceSpec {
    /// An expression linear in the state (gains and parameters allowed in
    /// its coefficients).
    Expr(Expr),
    /// `s = c x` with `c` chosen so that the sliding dynamics (the dynamics
    /// on `s = 0` under the equivalent control), linearized about 0, have
    /// these poles `(re, im)`: Ackermann's formula of Ackermann and Utkin.
    Poles(Vec<(f64, f64)>),
}

/// One mode of a hybrid controller.
#[derive(Clone, Debug, PartialEq)]
pub struct ModeSpec {
    /// Mode name.
    pub name: String,
    /// The controller of the file that drives the input in this mode.
    pub controller: String,
    /// Whether the mode may drive the input with the pendulum anywhere
    /// (`swing_up`); other modes are balancing modes.
    pub swing_up: bool,
}

/// A switch condition: comparisons `lhs op rhs` over the state (and
/// parameters), joined by and/or.
#[derive(Clone, Debug, PartialEq)]
pub enum Guard {
    /// `lhs op rhs`.
    Cmp {
        /// Operator.
        op: CmpOp,
        /// Left side.
        lhs: Expr,
        /// Right side.
        rhs: Expr,
    },
    /// Both hold.
    And(Box<Guard>, Box<Guard>),
    /// Either holds.
    Or(Box<Guard>, Box<Guard>),
}

impl Guard {
    /// The comparisons left to right, as `(op, lhs - rhs)`: the margins a
    /// numeric evaluation computes (see [`Guard::holds`]).
    pub fn margins(&self) -> Vec<(CmpOp, Expr)> {
        match self {
            Guard::Cmp { op, lhs, rhs } => vec![(*op, *lhs - *rhs)],
            Guard::And(a, b) | Guard::Or(a, b) => {
                let mut v = a.margins();
                v.extend(b.margins());
                v
            }
        }
    }

    /// Whether the condition holds, given the values of [`Guard::margins`]
    /// starting at `margins[*next]` (advanced past this guard's comparisons).
    pub fn holds(&self, margins: &[f64], next: &mut usize) -> bool {
        match self {
            Guard::Cmp { op, .. } => {
                let m = margins.get(*next).copied().unwrap_or(f64::NAN);
                *next += 1;
                op.holds(m)
            }
            Guard::And(a, b) => {
                let x = a.holds(margins, next);
                let y = b.holds(margins, next);
                x && y
            }
            Guard::Or(a, b) => {
                let x = a.holds(margins, next);
                let y = b.holds(margins, next);
                x || y
            }
        }
    }
}

impl std::fmt::Display for Guard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Guard::Cmp { op, lhs, rhs } => write!(f, "{lhs} {} {rhs}", op.symbol()),
            Guard::And(a, b) => write!(f, "({a}) and ({b})"),
            Guard::Or(a, b) => write!(f, "({a}) or ({b})"),
        }
    }
}

/// `switch from -> to when condition`.
#[derive(Clone, Debug, PartialEq)]
pub struct SwitchSpec {
    /// Index of the mode switched from.
    pub from: usize,
    /// Index of the mode switched to.
    pub to: usize,
    /// The condition.
    pub when: Guard,
    /// The condition as written in the file.
    pub text: String,
}
