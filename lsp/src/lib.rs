//! plantc-lsp: a language server for `.plant` model files, on `lsp-server`
//! and `lsp-types`.
//!
//! It gives the editor what `plantc check` knows, as you type: diagnostics
//! (the messages of `check`, with quick fixes where the help names one),
//! hover (parameters, lets and their derived units, effects, coordinates,
//! units), inlay hints (the derived unit of lets, energies and forces), go
//! to definition, references and rename (through the lossless editor of
//! `plantc-derive`), completion, the outline, semantic tokens and formatting
//! (`plantc fmt`'s layout). Documents are synced incrementally; positions are
//! UTF-16 as LSP requires.
//!
//! Entry points: [`run_stdio`] (what `plantc lsp` calls: the bounded framing
//! of [`transport`], so no frame ends the server) and [`serve`] on any
//! [`lsp_server::Connection`] (tests and benches use an in-memory one).

mod analysis;
mod complete;
mod diagnostics;
mod document;
mod hover;
mod inlay;
mod navigate;
mod outline;
mod server;
mod tokens;
pub mod transport;

pub use analysis::Analysis;
pub use diagnostics::MAX_PUBLISHED;
pub use document::Document;
pub use server::{capabilities, run_stdio, serve, ServerError, State};
