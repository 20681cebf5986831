//! Semantic tokens: every token of the file classified by what it denotes
//! (a coordinate, a parameter, an effect, a unit...).

use crate::analysis::Analysis;
use lsp_types::{
    SemanticToken, SemanticTokenModifier, SemanticTokenType, SemanticTokens, SemanticTokensLegend,
};
use plantc_derive::lang::check::SymbolKind;
use plantc_derive::lang::lexer::{lex, Tok};
use plantc_derive::lang::parser::KEYWORDS;
use plantc_derive::lang::visit::{Role, SymbolRef};

/// Token types, in legend order.
const TYPES: &[SemanticTokenType] = &[
    SemanticTokenType::KEYWORD,
    SemanticTokenType::VARIABLE,
    SemanticTokenType::PARAMETER,
    SemanticTokenType::PROPERTY,
    SemanticTokenType::FUNCTION,
    SemanticTokenType::MACRO,
    SemanticTokenType::TYPE,
    SemanticTokenType::NUMBER,
    SemanticTokenType::STRING,
    SemanticTokenType::COMMENT,
    SemanticTokenType::OPERATOR,
    SemanticTokenType::NAMESPACE,
];
const KEYWORD: u32 = 0;
const VARIABLE: u32 = 1;
const PARAMETER: u32 = 2;
const PROPERTY: u32 = 3;
const FUNCTION: u32 = 4;
const MACRO: u32 = 5;
const TYPE: u32 = 6;
const NUMBER: u32 = 7;
const STRING: u32 = 8;
const COMMENT: u32 = 9;
const OPERATOR: u32 = 10;
const NAMESPACE: u32 = 11;

/// Modifiers, in legend order (bits).
const MODIFIERS: &[SemanticTokenModifier] = &[
    SemanticTokenModifier::DECLARATION,
    SemanticTokenModifier::READONLY,
    SemanticTokenModifier::DEFAULT_LIBRARY,
];
const DECLARATION: u32 = 1;
const READONLY: u32 = 2;
const DEFAULT_LIBRARY: u32 = 4;

/// Words that are keywords where they are written (besides statement keywords).
pub const CLAUSE_KEYWORDS: &[&str] = &[
    "limits",
    "estimate",
    "angle",
    "length",
    "place",
    "poles",
    "lqr",
    "Q",
    "R",
    "gains",
    "linearize",
    "gain",
    "surface",
    "mode",
    "swing_up",
    "switch",
    "when",
    "and",
    "or",
    "wrap",
];

/// The legend announced in the server capabilities.
pub fn legend() -> SemanticTokensLegend {
    SemanticTokensLegend {
        token_types: TYPES.to_vec(),
        token_modifiers: MODIFIERS.to_vec(),
    }
}

/// All tokens of the document, encoded relative to each other as LSP requires.
pub fn semantic_tokens(a: &Analysis) -> SemanticTokens {
    let text = a.text();
    let mut diags = Vec::new();
    let toks = lex(text, &mut diags);
    let units = a.unit_spans();
    let in_unit = |s: usize| units.iter().any(|u| u.start <= s && s < u.end);
    // (start, end, type, modifiers)
    let mut out: Vec<(usize, usize, u32, u32)> = Vec::new();
    let mut prev_end = 0;
    let mut occ = a.occurrences.iter().peekable();
    for t in &toks {
        if let Some(i) = text[prev_end..t.span.start].find('#') {
            let c = prev_end + i;
            let end = text[c..t.span.start].trim_end().len() + c;
            out.push((c, end, COMMENT, 0));
        }
        prev_end = t.span.end;
        let (s, e) = (t.span.start, t.span.end);
        let class = match &t.tok {
            Tok::Ident => {
                while occ.peek().is_some_and(|o| o.span.start < s) {
                    occ.next();
                }
                let o = occ.peek().filter(|o| o.span.start == s);
                let word = &text[s..e];
                match o {
                    Some(o) => {
                        let decl = if o.role == Role::Declaration {
                            DECLARATION
                        } else {
                            0
                        };
                        let (ty, m) = match &o.symbol {
                            SymbolRef::Model(n) => match a.kind_of(n) {
                                Some(SymbolKind::Coordinate(_)) => (VARIABLE, 0),
                                Some(SymbolKind::Input) => (PROPERTY, 0),
                                Some(SymbolKind::Parameter) => (PARAMETER, READONLY),
                                Some(_) => (VARIABLE, READONLY),
                                None => (VARIABLE, 0),
                            },
                            SymbolRef::Gain(..) => (PARAMETER, READONLY),
                            SymbolRef::Surface(..) => (VARIABLE, READONLY),
                            SymbolRef::Mode(..) => (VARIABLE, 0),
                            SymbolRef::LawOutput(_) => (VARIABLE, 0),
                            SymbolRef::Block(_) => (NAMESPACE, 0),
                            SymbolRef::Builtin(_) => (FUNCTION, DEFAULT_LIBRARY),
                            SymbolRef::Effect(_) => (MACRO, 0),
                            SymbolRef::UnknownFunction(_) => (FUNCTION, 0),
                        };
                        Some((ty, m | decl))
                    }
                    None if in_unit(s) => Some((TYPE, 0)),
                    None if word == "pi" => Some((VARIABLE, READONLY | DEFAULT_LIBRARY)),
                    None if KEYWORDS.contains(&word) || CLAUSE_KEYWORDS.contains(&word) => {
                        Some((KEYWORD, 0))
                    }
                    None => None,
                }
            }
            Tok::Number | Tok::Imag => Some((NUMBER, 0)),
            Tok::Str(_) => Some((STRING, 0)),
            Tok::Plus
            | Tok::Minus
            | Tok::Star
            | Tok::Slash
            | Tok::Caret
            | Tok::Eq
            | Tok::Prime
            | Tok::Colon => Some((OPERATOR, 0)),
            _ => None,
        };
        if let Some((ty, m)) = class {
            out.push((s, e, ty, m));
        }
    }
    let mut data = Vec::with_capacity(out.len());
    let (mut line, mut col) = (0u32, 0u32);
    for (s, e, ty, m) in out {
        let p = a.doc.position(s);
        let len = text[s..e].encode_utf16().count() as u32;
        if len == 0 {
            continue;
        }
        let delta_line = p.line - line;
        let delta_start = if delta_line == 0 {
            p.character - col
        } else {
            p.character
        };
        data.push(SemanticToken {
            delta_line,
            delta_start,
            length: len,
            token_type: ty,
            token_modifiers_bitset: m,
        });
        line = p.line;
        col = p.character;
    }
    SemanticTokens {
        result_id: None,
        data,
    }
}
