//! The canonical layout of a model file (`plantc fmt`, the language server's
//! formatting).
//!
//! The formatter works on tokens and lines, not on the tree, so syntax added
//! to the language is laid out without changes here. The layout:
//! - one space between tokens, except none inside `( )` and `[ ]` next to the
//!   brackets, before `,` and `'`, around `* / ^`, after a unary sign, between
//!   a function name and `(`, and inside a complex literal (`-2+3.464i`);
//!   binary `+ -`, `=` and `:` are spaced;
//! - statements start in column 0, entries of `{ }` blocks in column 4, one
//!   per line (`{` ends its header line, `}` is alone on its line);
//!   continuation lines are indented to the column of the statement's first
//!   `=` (or 4 past the statement when it has none); line breaks inside a
//!   statement are kept;
//! - one-line statements of the same keyword form a table (blank and comment
//!   lines between them do not end it; any other statement does) whose columns (keyword, name and value, `: kind`, doc string, `estimate [..]`,
//!   `limits [..]`) are aligned;
//! - comments are kept where they are; trailing comments of consecutive lines
//!   are aligned two spaces after the longest line;
//! - at most one blank line in a row, none at the start and end of the file or
//!   of a block; no trailing spaces; the file ends with one line end (`\r\n`
//!   if the file used it).
//!
//! [`format()`] refuses a file with syntax errors, and checks its own output:
//! the same tokens, the same comments, and the same statements and
//! expressions after parsing again; otherwise it returns an error and the
//! text is left as it was.

use super::ast::ModelFile;
use super::diagnostic::Diagnostic;
use super::lexer::{lex, Tok, Token};
use super::parser::parse;
use super::visit::root_exprs;
use std::fmt;

/// Why a file was not formatted.
#[derive(Debug, Clone, PartialEq)]
pub enum FormatError {
    /// The file has syntax errors (these); it is left as it is.
    Syntax(Vec<Diagnostic>),
    /// The formatted text would not mean the same as the original (a bug of
    /// the formatter; the text is left as it is).
    Unstable(String),
}

impl fmt::Display for FormatError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FormatError::Syntax(d) => write!(
                f,
                "the file has {} syntax error(s); fix them before formatting",
                d.len()
            ),
            FormatError::Unstable(why) => write!(
                f,
                "the formatter would change the meaning of the file ({why}); it was left unchanged, please report this"
            ),
        }
    }
}

impl std::error::Error for FormatError {}

/// The file in its canonical layout (see the module documentation).
pub fn format(text: &str) -> Result<String, FormatError> {
    let (file, diags) = parse(text);
    let errors: Vec<Diagnostic> = diags.into_iter().filter(|d| d.is_error()).collect();
    if !errors.is_empty() {
        return Err(FormatError::Syntax(errors));
    }
    let out = layout(text);
    verify(text, &file, &out)?;
    Ok(out)
}

/// True if the file is already in its canonical layout (and has no syntax errors).
pub fn is_formatted(text: &str) -> Result<bool, FormatError> {
    format(text).map(|f| f == text)
}

/// The comments of a text (`#` to the end of the line, trailing blanks
/// removed), in order.
pub fn comments(text: &str) -> Vec<String> {
    let mut d = Vec::new();
    let toks = lex(text, &mut d);
    let mut out = Vec::new();
    let mut prev = 0;
    for t in &toks {
        if let Some(c) = comment_in(&text[prev..t.span.start]) {
            out.push(c);
        }
        prev = t.span.end;
    }
    out
}

fn comment_in(gap: &str) -> Option<String> {
    gap.find('#').map(|i| gap[i..].trim_end().to_string())
}

fn verify(text: &str, before: &ModelFile, out: &str) -> Result<(), FormatError> {
    let sig = |s: &str| -> Vec<(Tok, String)> {
        let mut d = Vec::new();
        lex(s, &mut d)
            .into_iter()
            .filter(|t| t.tok != Tok::Newline)
            .map(|t| (t.tok, s[t.span.start..t.span.end].to_string()))
            .collect()
    };
    if sig(text) != sig(out) {
        return Err(FormatError::Unstable("tokens differ".into()));
    }
    if comments(text) != comments(out) {
        return Err(FormatError::Unstable("comments differ".into()));
    }
    let (after, diags) = parse(out);
    if diags.iter().any(|d| d.is_error()) {
        return Err(FormatError::Unstable(format!(
            "the result does not parse: {}",
            diags[0].message
        )));
    }
    let shape = |f: &ModelFile| {
        let exprs: Vec<String> = root_exprs(f)
            .into_iter()
            .map(|(e, _)| e.to_string())
            .collect();
        let counts = [
            f.coordinates.len(),
            f.inputs.len(),
            f.outputs.len(),
            f.parameters.len(),
            f.lets.len(),
            f.kinetic.len(),
            f.potential.len(),
            f.forces.len(),
            f.sensors.len(),
            f.actuators.len(),
            f.sets.len(),
            f.controllers.len(),
        ];
        let blocks: Vec<usize> = f
            .sets
            .iter()
            .map(|s| s.entries.len())
            .chain(f.controllers.iter().map(|c| c.body.len()))
            .collect();
        (exprs, counts, blocks)
    };
    if shape(before) != shape(&after) {
        return Err(FormatError::Unstable(
            "the statements or expressions differ after parsing again".into(),
        ));
    }
    Ok(())
}

/// A physical line split into code tokens and an optional trailing comment.
struct Line {
    toks: Vec<Token>,
    comment: Option<String>,
}

/// What the output is made of, before alignment.
enum Item {
    Blank,
    /// A comment alone on its line, with its indentation.
    Comment(usize, String),
    Code(CodeLine),
}

struct CodeLine {
    indent: usize,
    /// Rendered cells (see [`cells`]); the line is their join with single spaces
    /// unless aligned in a table.
    cells: Vec<String>,
    comment: Option<String>,
    /// First token's text when the line is a whole one-line statement (a table row).
    row_key: Option<String>,
}

impl CodeLine {
    fn text(&self) -> String {
        format!("{}{}", " ".repeat(self.indent), self.cells.join(" "))
    }
}

fn is_operand_end(t: &Tok) -> bool {
    matches!(
        t,
        Tok::Number | Tok::Imag | Tok::Ident | Tok::RParen | Tok::RBracket | Tok::Prime
    )
}

fn splits_lines(text: &str) -> Vec<Line> {
    let mut diags = Vec::new();
    let toks = lex(text, &mut diags);
    let mut lines = Vec::new();
    let mut cur = Line {
        toks: Vec::new(),
        comment: None,
    };
    let mut prev_end = 0;
    for t in toks {
        if let Some(c) = comment_in(&text[prev_end..t.span.start]) {
            cur.comment = Some(c);
        }
        prev_end = t.span.end;
        match t.tok {
            Tok::Newline => lines.push(std::mem::replace(
                &mut cur,
                Line {
                    toks: Vec::new(),
                    comment: None,
                },
            )),
            Tok::Eof => {
                if !cur.toks.is_empty() || cur.comment.is_some() {
                    lines.push(cur);
                }
                break;
            }
            _ => cur.toks.push(t),
        }
    }
    // `{` ends its line and `}` starts its own
    let mut out = Vec::new();
    for line in lines {
        let mut seg: Vec<Token> = Vec::new();
        let n = line.toks.len();
        for (i, t) in line.toks.into_iter().enumerate() {
            if t.tok == Tok::RBrace && !seg.is_empty() {
                out.push(Line {
                    toks: std::mem::take(&mut seg),
                    comment: None,
                });
            }
            let open = t.tok == Tok::LBrace;
            seg.push(t);
            if open && i + 1 < n {
                out.push(Line {
                    toks: std::mem::take(&mut seg),
                    comment: None,
                });
            }
        }
        out.push(Line {
            toks: seg,
            comment: line.comment,
        });
    }
    out
}

/// Renders the tokens of one line; `prev` is the last code token before the
/// line (decides whether a leading `+`/`-` is binary). Returns the cells.
fn cells(src: &str, toks: &[Token], mut prev: Option<Tok>) -> Vec<String> {
    let text = |t: &Token| &src[t.span.start..t.span.end];
    let mut cells: Vec<String> = Vec::new();
    let mut cur = String::new();
    let mut depth = 0usize;
    // whether the last `+`/`-` emitted was binary
    let mut last_sign_binary = false;
    for (i, t) in toks.iter().enumerate() {
        let next_is_imag = toks.get(i + 1).is_some_and(|n| n.tok == Tok::Imag);
        let sign = matches!(t.tok, Tok::Plus | Tok::Minus);
        let binary = sign && prev.as_ref().is_some_and(is_operand_end);
        let complex = sign && next_is_imag && prev == Some(Tok::Number);
        if i > 0 {
            let p = prev.clone().unwrap_or(Tok::Eof);
            let split = depth == 0
                && (matches!(t.tok, Tok::Str(_) | Tok::Colon)
                    || (t.tok == Tok::Ident
                        && matches!(
                            p,
                            Tok::Ident | Tok::Number | Tok::RBracket | Tok::Str(_) | Tok::Prime
                        )));
            let space = match (&p, &t.tok) {
                (_, Tok::RParen | Tok::RBracket | Tok::Comma | Tok::Prime) => false,
                (Tok::LParen | Tok::LBracket, _) => false,
                (Tok::Star | Tok::Slash | Tok::Caret, _)
                | (_, Tok::Star | Tok::Slash | Tok::Caret) => false,
                (Tok::Ident, Tok::LParen) => false,
                (_, Tok::Plus | Tok::Minus) => !complex,
                (Tok::Plus | Tok::Minus, _) => last_sign_binary,
                _ => true,
            };
            if split {
                cells.push(std::mem::take(&mut cur));
            } else if space {
                cur.push(' ');
            }
        }
        cur.push_str(text(t));
        if sign {
            last_sign_binary = binary && !complex;
        }
        match t.tok {
            Tok::LParen | Tok::LBracket => depth += 1,
            Tok::RParen | Tok::RBracket => depth = depth.saturating_sub(1),
            _ => {}
        }
        prev = Some(t.tok.clone());
    }
    cells.push(cur);
    cells
}

fn is_continuing_op(t: &Tok) -> bool {
    matches!(
        t,
        Tok::Plus | Tok::Minus | Tok::Star | Tok::Slash | Tok::Caret | Tok::Comma | Tok::Eq
    )
}

fn layout(text: &str) -> String {
    let nl = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let lines = splits_lines(text);
    let mut items: Vec<Item> = Vec::new();
    // comment and blank lines wait for the next code line, which decides their indentation
    let mut pending: Vec<Option<String>> = Vec::new();
    let mut brace = 0usize;
    let mut paren = 0usize;
    let mut prev: Option<Tok> = None;
    let mut cont_indent = 4usize;
    let mut in_stmt = false;
    // index in `items` of the current statement's first line, and whether it got a continuation
    let mut stmt_item: Option<usize> = None;
    let flush = |items: &mut Vec<Item>, pending: &mut Vec<Option<String>>, indent: usize| {
        for p in pending.drain(..) {
            items.push(match p {
                None => Item::Blank,
                Some(c) => Item::Comment(indent, c),
            });
        }
    };
    for line in &lines {
        let Some(first) = line.toks.first() else {
            pending.push(line.comment.clone());
            continue;
        };
        let continuation = in_stmt
            && (paren > 0
                || prev.as_ref().is_some_and(is_continuing_op)
                || matches!(first.tok, Tok::Plus | Tok::Minus));
        let closing = first.tok == Tok::RBrace;
        let indent = if continuation {
            cont_indent
        } else {
            let d = if closing {
                brace.saturating_sub(1)
            } else {
                brace
            };
            d * 4
        };
        let comment_indent = if continuation { cont_indent } else { brace * 4 };
        flush(&mut items, &mut pending, comment_indent);
        let rendered = cells(text, &line.toks, prev.clone());
        if continuation {
            if let Some(Item::Code(c)) = stmt_item.and_then(|i| items.get_mut(i)) {
                c.row_key = None;
            }
        } else {
            let joined = rendered.join(" ");
            cont_indent = match eq_column(&joined) {
                Some(col) => indent + col,
                None => indent + 4,
            };
            stmt_item = Some(items.len());
        }
        for t in &line.toks {
            match t.tok {
                Tok::LParen | Tok::LBracket => paren += 1,
                Tok::RParen | Tok::RBracket => paren = paren.saturating_sub(1),
                Tok::LBrace => brace += 1,
                Tok::RBrace => brace = brace.saturating_sub(1),
                _ => {}
            }
        }
        let last = line.toks.last().map(|t| t.tok.clone());
        let opens = last == Some(Tok::LBrace);
        // a statement ends at a line end outside brackets, unless an operator continues it
        in_stmt = !opens && !closing;
        let row_key = (!continuation && !opens && !closing)
            .then(|| text[first.span.start..first.span.end].to_string());
        items.push(Item::Code(CodeLine {
            indent,
            cells: rendered,
            comment: line.comment.clone(),
            row_key,
        }));
        prev = last;
        if opens || closing {
            stmt_item = None;
        }
    }
    flush(&mut items, &mut pending, 0);
    normalize_blanks(&mut items);
    align_tables(&mut items);
    let mut texts: Vec<(String, Option<String>)> = items
        .iter()
        .map(|it| match it {
            Item::Blank => (String::new(), None),
            Item::Comment(i, c) => (format!("{}{c}", " ".repeat(*i)), None),
            Item::Code(c) => (c.text(), c.comment.clone()),
        })
        .collect();
    align_comments(&mut texts, &items);
    let mut out = String::new();
    for (t, c) in texts {
        out.push_str(&t);
        if let Some(c) = c {
            out.push_str(&c);
        }
        let trimmed = out.trim_end_matches([' ', '\t']).len();
        out.truncate(trimmed);
        out.push_str(nl);
    }
    out
}

/// Column (in chars) of the first `=` outside brackets and strings of a rendered line.
fn eq_column(line: &str) -> Option<usize> {
    let mut depth = 0i32;
    let mut in_str = false;
    let mut escaped = false;
    for (col, c) in line.chars().enumerate() {
        if escaped {
            escaped = false;
            continue;
        }
        match c {
            '\\' if in_str => escaped = true,
            '"' => in_str = !in_str,
            '(' | '[' if !in_str => depth += 1,
            ')' | ']' if !in_str => depth -= 1,
            '=' if !in_str && depth == 0 => return Some(col),
            _ => {}
        }
    }
    None
}

fn is_open(it: &Item) -> bool {
    matches!(it, Item::Code(c) if c.cells.last().is_some_and(|s| s.ends_with('{')))
}

fn is_close(it: &Item) -> bool {
    matches!(it, Item::Code(c) if c.cells.first().is_some_and(|s| s.starts_with('}')))
}

fn normalize_blanks(items: &mut Vec<Item>) {
    let mut out: Vec<Item> = Vec::with_capacity(items.len());
    for it in items.drain(..) {
        if matches!(it, Item::Blank) {
            let skip = match out.last() {
                None | Some(Item::Blank) => true,
                Some(p) => is_open(p),
            };
            if skip {
                continue;
            }
        }
        if is_close(&it) {
            while matches!(out.last(), Some(Item::Blank)) {
                out.pop();
            }
        }
        out.push(it);
    }
    while matches!(out.last(), Some(Item::Blank)) {
        out.pop();
    }
    *items = out;
}

/// Aligns the columns of runs of one-line statements with the same keyword.
fn align_tables(items: &mut [Item]) {
    let mut i = 0;
    while i < items.len() {
        let key = match &items[i] {
            Item::Code(c) => c.row_key.clone(),
            _ => None,
        };
        let Some(key) = key else {
            i += 1;
            continue;
        };
        let indent = match &items[i] {
            Item::Code(c) => c.indent,
            _ => 0,
        };
        // the table goes on over blank and comment lines
        let mut j = i;
        let mut end = i;
        while j < items.len() {
            match &items[j] {
                Item::Blank | Item::Comment(..) => {}
                Item::Code(c)
                    if c.row_key.as_deref() == Some(key.as_str()) && c.indent == indent =>
                {
                    end = j + 1
                }
                _ => break,
            }
            j += 1;
        }
        let j = end;
        let nrows = items[i..j]
            .iter()
            .filter(|it| matches!(it, Item::Code(_)))
            .count();
        if nrows >= 2 {
            let rows: Vec<&mut CodeLine> = items[i..j]
                .iter_mut()
                .filter_map(|it| match it {
                    Item::Code(c) => Some(c),
                    _ => None,
                })
                .collect();
            let ncol = rows.iter().map(|r| r.cells.len()).max().unwrap_or(0);
            let mut width = vec![0usize; ncol];
            for r in &rows {
                for (k, c) in r.cells.iter().enumerate() {
                    if k + 1 < r.cells.len() {
                        width[k] = width[k].max(c.chars().count());
                    }
                }
            }
            for r in rows {
                let n = r.cells.len();
                for (k, c) in r.cells.iter_mut().enumerate() {
                    if k + 1 < n {
                        let pad = width[k].saturating_sub(c.chars().count());
                        c.push_str(&" ".repeat(pad));
                    }
                }
            }
        }
        i = j.max(i + 1);
    }
}

/// Aligns trailing comments of consecutive code lines.
fn align_comments(texts: &mut [(String, Option<String>)], items: &[Item]) {
    let mut i = 0;
    while i < texts.len() {
        if texts[i].1.is_none() || !matches!(items[i], Item::Code(_)) {
            i += 1;
            continue;
        }
        let mut j = i;
        while j < texts.len() && texts[j].1.is_some() && matches!(items[j], Item::Code(_)) {
            j += 1;
        }
        let col = texts[i..j]
            .iter()
            .map(|(t, _)| t.trim_end().chars().count())
            .max()
            .unwrap_or(0)
            + 2;
        for (t, c) in texts[i..j].iter_mut() {
            let base = t.trim_end().to_string();
            let pad = col - base.chars().count();
            *t = format!("{base}{}", " ".repeat(pad));
            let _ = c;
        }
        i = j;
    }
}
