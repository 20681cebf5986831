//! The symbolic core: a hash-consed expression DAG with exact rational
//! constants, differentiation, substitution, a canonical form that recognises
//! identically zero expressions, printing (plain and LaTeX) and compiled numeric
//! tapes.

pub mod diff;
pub mod expr;
pub mod print;
pub mod rational;
pub mod subst;

pub use diff::{diff, jacobian, time_derivative, CoordinateSymbols};
pub use expr::{Expr, Func, Node, Symbol};
pub use rational::Rational;
pub use subst::{substitute, substitute_symbols};
