//! Tokenizer for `.plant` files.
//!
//! Comments (`#` to end of line) and blanks are dropped; line ends are kept as
//! [`Tok::Newline`] tokens because statements end at a newline.

use super::diagnostic::Diagnostic;
use super::span::Span;

/// Token kinds. Identifier and number text is the source slice under the span.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Tok {
    /// Identifier or keyword.
    Ident,
    /// Decimal or exponent number literal, e.g. `0.257`, `9.98e-4`.
    Number,
    /// Imaginary literal: a number immediately followed by `i`, e.g. `3.464i`.
    Imag,
    /// String literal with its unescaped value.
    Str(String),
    /// End of a line.
    Newline,
    /// `(`
    LParen,
    /// `)`
    RParen,
    /// `[`
    LBracket,
    /// `]`
    RBracket,
    /// `{`
    LBrace,
    /// `}`
    RBrace,
    /// `,`
    Comma,
    /// `=`
    Eq,
    /// `+`
    Plus,
    /// `-`
    Minus,
    /// `*`
    Star,
    /// `/`
    Slash,
    /// `^`
    Caret,
    /// `'` (time derivative)
    Prime,
    /// `:`
    Colon,
    /// `<` (controller switch conditions)
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
    /// `->` (controller mode switches)
    Arrow,
    /// End of input.
    Eof,
}

impl Tok {
    /// Human-readable description used in "expected ..., found ..." messages.
    pub fn describe(&self) -> &'static str {
        match self {
            Tok::Ident => "a name",
            Tok::Number => "a number",
            Tok::Imag => "an imaginary number",
            Tok::Str(_) => "a string",
            Tok::Newline => "end of line",
            Tok::LParen => "`(`",
            Tok::RParen => "`)`",
            Tok::LBracket => "`[`",
            Tok::RBracket => "`]`",
            Tok::LBrace => "`{`",
            Tok::RBrace => "`}`",
            Tok::Comma => "`,`",
            Tok::Eq => "`=`",
            Tok::Plus => "`+`",
            Tok::Minus => "`-`",
            Tok::Star => "`*`",
            Tok::Slash => "`/`",
            Tok::Caret => "`^`",
            Tok::Prime => "`'`",
            Tok::Colon => "`:`",
            Tok::Lt => "`<`",
            Tok::Le => "`<=`",
            Tok::Gt => "`>`",
            Tok::Ge => "`>=`",
            Tok::Arrow => "`->`",
            Tok::Eof => "end of file",
        }
    }
}

/// A token with its location.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Token {
    /// Kind.
    pub tok: Tok,
    /// Location.
    pub span: Span,
}

fn is_ident_start(c: char) -> bool {
    c.is_ascii_alphabetic() || c == '_'
}

fn is_ident_continue(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Splits `text` into tokens; lexical errors are appended to `diags` and the
/// offending characters skipped. The result always ends with [`Tok::Eof`].
pub fn lex(text: &str, diags: &mut Vec<Diagnostic>) -> Vec<Token> {
    let bytes = text.as_bytes();
    let mut toks = Vec::new();
    let mut i = 0;
    let n = text.len();
    let at = |i: usize| -> char { text[i..].chars().next().unwrap_or('\0') };
    while i < n {
        let c = at(i);
        let start = i;
        let single = |t: Tok| Some(t);
        let next = if i + 1 < n { bytes[i + 1] } else { 0 };
        let two = match (c, next) {
            ('<', b'=') => Some(Tok::Le),
            ('>', b'=') => Some(Tok::Ge),
            ('-', b'>') => Some(Tok::Arrow),
            _ => None,
        };
        if let Some(t) = two {
            i += 2;
            toks.push(Token {
                tok: t,
                span: Span::new(start, i),
            });
            continue;
        }
        let kind = match c {
            ' ' | '\t' | '\r' => {
                i += 1;
                continue;
            }
            '#' => {
                while i < n && bytes[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            '\n' => single(Tok::Newline),
            '(' => single(Tok::LParen),
            ')' => single(Tok::RParen),
            '[' => single(Tok::LBracket),
            ']' => single(Tok::RBracket),
            '{' => single(Tok::LBrace),
            '}' => single(Tok::RBrace),
            ',' => single(Tok::Comma),
            '=' => single(Tok::Eq),
            '+' => single(Tok::Plus),
            '-' => single(Tok::Minus),
            '*' => single(Tok::Star),
            '/' => single(Tok::Slash),
            '^' => single(Tok::Caret),
            '\'' => single(Tok::Prime),
            ':' => single(Tok::Colon),
            '<' => single(Tok::Lt),
            '>' => single(Tok::Gt),
            _ => None,
        };
        if let Some(t) = kind {
            i += 1;
            toks.push(Token {
                tok: t,
                span: Span::new(start, i),
            });
            continue;
        }
        if c == '"' {
            i += 1;
            let mut value = String::new();
            let mut closed = false;
            while i < n {
                let ch = at(i);
                if ch == '\n' {
                    break;
                }
                i += ch.len_utf8();
                if ch == '"' {
                    closed = true;
                    break;
                }
                if ch == '\\' && i < n {
                    let e = at(i);
                    if e == '"' || e == '\\' {
                        value.push(e);
                        i += 1;
                        continue;
                    }
                }
                value.push(ch);
            }
            let mut end = i;
            if !closed {
                // do not include a trailing '\r' in the span
                if end > start + 1 && bytes[end - 1] == b'\r' {
                    end -= 1;
                }
                diags.push(
                    Diagnostic::error(
                        "plantc::unterminated_string",
                        "unterminated string",
                        Span::new(start, end),
                        "this string is not closed before the end of the line",
                    )
                    .with_help("close it with `\"` on the same line; strings cannot span lines"),
                );
            }
            toks.push(Token {
                tok: Tok::Str(value),
                span: Span::new(start, end),
            });
            continue;
        }
        if c.is_ascii_digit() || (c == '.' && i + 1 < n && bytes[i + 1].is_ascii_digit()) {
            while i < n && bytes[i].is_ascii_digit() {
                i += 1;
            }
            if i < n && bytes[i] == b'.' && i + 1 < n && bytes[i + 1].is_ascii_digit() {
                i += 1;
                while i < n && bytes[i].is_ascii_digit() {
                    i += 1;
                }
            }
            if i < n && (bytes[i] == b'e' || bytes[i] == b'E') {
                let mut j = i + 1;
                if j < n && (bytes[j] == b'+' || bytes[j] == b'-') {
                    j += 1;
                }
                if j < n && bytes[j].is_ascii_digit() {
                    while j < n && bytes[j].is_ascii_digit() {
                        j += 1;
                    }
                    i = j;
                }
            }
            let mut tok = Tok::Number;
            if i < n && bytes[i] == b'i' && !(i + 1 < n && is_ident_continue(at(i + 1))) {
                i += 1;
                tok = Tok::Imag;
            }
            toks.push(Token {
                tok,
                span: Span::new(start, i),
            });
            continue;
        }
        if is_ident_start(c) {
            while i < n && is_ident_continue(at(i)) {
                i += 1;
            }
            toks.push(Token {
                tok: Tok::Ident,
                span: Span::new(start, i),
            });
            continue;
        }
        i += c.len_utf8();
        let help = if c.is_alphabetic() {
            "names use ASCII letters, digits and `_` only (e.g. `alpha`, not `α`)"
        } else {
            "remove it; comments start with `#`"
        };
        diags.push(
            Diagnostic::error(
                "plantc::unexpected_character",
                format!("unexpected character `{c}`"),
                Span::new(start, i),
                "not part of the model language",
            )
            .with_help(help),
        );
    }
    toks.push(Token {
        tok: Tok::Eof,
        span: Span::new(n, n),
    });
    toks
}
