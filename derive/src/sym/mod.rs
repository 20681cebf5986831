//! The symbolic core: a hash-consed expression DAG with exact rational
//! constants, differentiation, substitution, a canonical form that recognises
//! identically zero expressions, printing (plain and LaTeX) and compiled numeric
//! tapes.

pub mod canonical;
pub mod diff;
pub mod dual;
pub mod expr;
pub(crate) mod fxhash;
mod jit;
pub mod poly;
pub mod present;
pub mod print;
pub mod rational;
pub mod subst;
pub mod tape;
pub mod trig;

pub use canonical::{
    canonical, equivalent, is_zero, simplify, try_canonical, try_is_zero, try_is_zero_within,
    try_simplify, try_simplify_within,
};
pub use diff::{diff, jacobian, time_derivative, CoordinateSymbols};
pub use dual::eval_jacobian;
pub use expr::{Evaluator, Expr, Func, Node, Symbol};
pub use poly::CanonError;
pub use present::{present, try_present, try_present_within, Canonicalizer, Name};
pub use rational::Rational;
pub use subst::{substitute, substitute_symbols, substitute_symbols_all};
pub use tape::{Instr, SplitTape, Tape, TapeError};
