//! The tree-sitter grammar of plantc model files (`.plant`), for editors and
//! tools that embed tree-sitter:
//!
//! ```ignore
//! let mut parser = tree_sitter::Parser::new();
//! parser.set_language(&tree_sitter_plant::LANGUAGE.into()).unwrap();
//! let tree = parser.parse("model m\n", None).unwrap();
//! ```
//!
//! `plantc check` and the language server are the authority on what a valid
//! model is; the grammar treats line ends as blanks (see `grammar.js`).

use tree_sitter_language::LanguageFn;

extern "C" {
    fn tree_sitter_plant() -> *const ();
}

/// The grammar (`tree_sitter::Language::from(LANGUAGE)`).
pub const LANGUAGE: LanguageFn = unsafe { LanguageFn::from_raw(tree_sitter_plant) };

/// The node types of the generated parser (`src/node-types.json`).
pub const NODE_TYPES: &str = include_str!("../../src/node-types.json");

/// The highlight query (`queries/highlights.scm`).
pub const HIGHLIGHTS_QUERY: &str = include_str!("../../queries/highlights.scm");
