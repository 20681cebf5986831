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
            // a byte-order mark opening the file (Windows editors write one)
            '\u{feff}' if i == 0 => {
                i += c.len_utf8();
                continue;
            }
            ' ' | '\t' => {
                i += 1;
                continue;
            }
            // `\r\n` ends a line at its `\n`; a lone `\r` (classic Mac) too
            '\r' if i + 1 < n && bytes[i + 1] == b'\n' => {
                i += 1;
                continue;
            }
            '#' => {
                while i < n && bytes[i] != b'\n' && bytes[i] != b'\r' {
                    i += 1;
                }
                continue;
            }
            '\n' | '\r' => single(Tok::Newline),
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
                if ch == '\n' || ch == '\r' {
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
            let end = i;
            if !closed {
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
            let digits_end = i;
            if i < n && bytes[i] == b'i' && !(i + 1 < n && is_ident_continue(at(i + 1))) {
                i += 1;
                tok = Tok::Imag;
            }
            if text[start..digits_end]
                .parse::<f64>()
                .is_ok_and(f64::is_infinite)
            {
                diags.push(
                    Diagnostic::error(
                        "plantc::number_out_of_range",
                        format!("`{}` is too large for a number", &text[start..digits_end]),
                        Span::new(start, digits_end),
                        "beyond 1.8e308: would be infinite",
                    )
                    .with_help("numbers must be finite; check the exponent"),
                );
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
        } else if invisible_name(c).is_some() {
            "delete it (it is invisible in most editors: delete the characters around the caret and type them again)"
        } else {
            "remove it; comments start with `#`"
        };
        diags.push(
            Diagnostic::error(
                "plantc::unexpected_character",
                format!("unexpected character {}", describe_char(c)),
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

/// The name of a character that shows as nothing (or garbles a terminal):
/// control characters, zero-width and direction marks, byte-order marks.
pub fn invisible_name(c: char) -> Option<&'static str> {
    Some(match c {
        '\0' => "NUL",
        '\u{200b}' => "zero-width space",
        '\u{200c}' => "zero-width non-joiner",
        '\u{200d}' => "zero-width joiner",
        '\u{2060}' => "word joiner",
        '\u{feff}' => "byte-order mark / zero-width no-break space",
        '\u{00a0}' => "no-break space",
        '\u{00ad}' => "soft hyphen",
        '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' => {
            "text-direction mark"
        }
        c if c.is_control() => "control character",
        _ => return None,
    })
}

/// A character for a message: `` `x` `` when visible, else its code point
/// and name (`U+200B (zero-width space)`), so nothing invisible or raw
/// control bytes reach the terminal.
pub fn describe_char(c: char) -> String {
    match invisible_name(c) {
        Some(name) => format!("U+{:04X} ({name})", c as u32),
        None => format!("`{c}`"),
    }
}
