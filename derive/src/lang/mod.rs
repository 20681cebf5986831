//! The `.plant` model language.
pub mod ast;
pub mod check;
pub mod diagnostic;
pub mod effects;
pub mod lexer;
pub mod parser;
pub mod source;
pub mod span;
pub mod units;

pub use check::{dimension_of, parse_and_check, Checked, Symbols};
pub use diagnostic::{render, Diagnostic, Severity};
pub use source::SourceFile;
pub use span::Span;
pub mod edit;
