//! Diagnostics (errors, warnings, notes) and their deterministic plain-text rendering.

use super::source::SourceFile;
use super::span::Span;
use std::fmt;

/// How serious a diagnostic is. Only errors make a model unusable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Severity {
    /// The model is invalid.
    Error,
    /// Suspicious but accepted.
    Warning,
    /// Information (e.g. a default that was applied).
    Note,
}

impl Severity {
    /// Lower-case name used in rendered output.
    pub fn as_str(self) -> &'static str {
        match self {
            Severity::Error => "error",
            Severity::Warning => "warning",
            Severity::Note => "note",
        }
    }
}

/// An extra labelled span shown with a diagnostic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Label {
    /// Where.
    pub span: Span,
    /// What to say there.
    pub text: String,
}

/// One problem found in a model file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// Error, warning or note.
    pub severity: Severity,
    /// Stable machine-readable code, e.g. `plantc::unit_mismatch`.
    pub code: &'static str,
    /// One-line summary.
    pub message: String,
    /// The main location.
    pub primary: Span,
    /// Text shown under the main location.
    pub label: String,
    /// Further related locations.
    pub secondary: Vec<Label>,
    /// A hint on how to fix it.
    pub help: Option<String>,
}

impl Diagnostic {
    /// A new error.
    pub fn error(
        code: &'static str,
        message: impl Into<String>,
        primary: Span,
        label: impl Into<String>,
    ) -> Diagnostic {
        Diagnostic {
            severity: Severity::Error,
            code,
            message: message.into(),
            primary,
            label: label.into(),
            secondary: Vec::new(),
            help: None,
        }
    }

    /// A new warning.
    pub fn warning(
        code: &'static str,
        message: impl Into<String>,
        primary: Span,
        label: impl Into<String>,
    ) -> Diagnostic {
        Diagnostic {
            severity: Severity::Warning,
            ..Diagnostic::error(code, message, primary, label)
        }
    }

    /// A new note.
    pub fn note(
        code: &'static str,
        message: impl Into<String>,
        primary: Span,
        label: impl Into<String>,
    ) -> Diagnostic {
        Diagnostic {
            severity: Severity::Note,
            ..Diagnostic::error(code, message, primary, label)
        }
    }

    /// Adds a help line.
    pub fn with_help(mut self, help: impl Into<String>) -> Diagnostic {
        self.help = Some(help.into());
        self
    }

    /// Adds a secondary label.
    pub fn with_label(mut self, span: Span, text: impl Into<String>) -> Diagnostic {
        self.secondary.push(Label {
            span,
            text: text.into(),
        });
        self
    }

    /// True for errors.
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Diagnostic {}

impl miette::Diagnostic for Diagnostic {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.code))
    }

    fn severity(&self) -> Option<miette::Severity> {
        Some(match self.severity {
            Severity::Error => miette::Severity::Error,
            Severity::Warning => miette::Severity::Warning,
            Severity::Note => miette::Severity::Advice,
        })
    }

    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.help
            .as_ref()
            .map(|h| Box::new(h) as Box<dyn fmt::Display + 'a>)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = miette::LabeledSpan> + '_>> {
        let primary = miette::LabeledSpan::new_primary_with_span(
            Some(self.label.clone()),
            (self.primary.start, self.primary.len()),
        );
        let rest = self.secondary.iter().map(|l| {
            miette::LabeledSpan::new_with_span(Some(l.text.clone()), (l.span.start, l.span.len()))
        });
        Some(Box::new(std::iter::once(primary).chain(rest)))
    }
}

/// At most this many diagnostics are rendered in full by [`render`]; the
/// summary line still counts them all.
pub const MAX_RENDERED: usize = 200;

/// One diagnostic as JSON: severity, code, message, the primary location
/// (1-based `line`/`column` and `end_line`/`end_column`, columns in
/// characters), label, help and the secondary labels as `related`. The shape
/// of `plantc check --json`'s `diagnostics`.
pub fn to_json(source: &SourceFile, d: &Diagnostic) -> serde_json::Value {
    let at = |span: Span| {
        let (line, column) = source.line_col(span.start);
        let (end_line, end_column) = source.line_col(span.end);
        serde_json::json!({
            "line": line,
            "column": column,
            "end_line": end_line,
            "end_column": end_column,
        })
    };
    let mut v = serde_json::json!({
        "severity": d.severity.as_str(),
        "code": d.code,
        "message": d.message,
        "file": source.name,
        "label": d.label,
        "help": d.help,
        "related": d.secondary.iter().map(|l| {
            let mut r = at(l.span);
            r["message"] = serde_json::Value::from(l.text.clone());
            r
        }).collect::<Vec<_>>(),
    });
    if let (Some(o), serde_json::Value::Object(p)) = (v.as_object_mut(), at(d.primary)) {
        o.extend(p);
    }
    v
}

/// Renders diagnostics as deterministic plain text (no colour, no terminal
/// width): a header `severity[code]: message`, a `--> file:line:col` line, the
/// source lines involved with `^` under the primary span and `-` under
/// secondary spans, then the help line. Ends with a count summary. Beyond
/// [`MAX_RENDERED`] diagnostics only the count is printed.
pub fn render(source: &SourceFile, diagnostics: &[Diagnostic]) -> String {
    let mut out = String::new();
    for d in diagnostics.iter().take(MAX_RENDERED) {
        render_one(source, d, &mut out);
        out.push('\n');
    }
    if diagnostics.len() > MAX_RENDERED {
        out.push_str(&format!(
            "... {} more diagnostics not shown (the first {MAX_RENDERED} are above; fix them first)\n",
            diagnostics.len() - MAX_RENDERED
        ));
    }
    let count = |s: Severity| diagnostics.iter().filter(|d| d.severity == s).count();
    let (e, w, n) = (
        count(Severity::Error),
        count(Severity::Warning),
        count(Severity::Note),
    );
    let plural = |k: usize, what: &str| format!("{k} {what}{}", if k == 1 { "" } else { "s" });
    out.push_str(&format!(
        "{}: {}, {}, {}\n",
        source.name,
        plural(e, "error"),
        plural(w, "warning"),
        plural(n, "note")
    ));
    out
}

/// Renders a single diagnostic (see [`render`]).
pub fn render_one(source: &SourceFile, d: &Diagnostic, out: &mut String) {
    let (line, col) = source.line_col(d.primary.start);
    out.push_str(&format!(
        "{}[{}]: {}\n",
        d.severity.as_str(),
        d.code,
        d.message
    ));
    // (line index, col start, width, is_primary, text)
    let mut marks: Vec<(usize, usize, usize, bool, &str)> = Vec::new();
    let p = locate(source, d.primary);
    marks.push((p.0, p.1, p.2, true, d.label.as_str()));
    for l in &d.secondary {
        let m = locate(source, l.span);
        marks.push((m.0, m.1, m.2, false, l.text.as_str()));
    }
    let max_line = marks.iter().map(|m| m.0 + 1).max().unwrap_or(1);
    let gw = max_line.to_string().len();
    let pad = " ".repeat(gw);
    out.push_str(&format!("{pad}--> {}:{}:{}\n", source.name, line, col));
    out.push_str(&format!("{pad} |\n"));
    let mut lines: Vec<usize> = marks.iter().map(|m| m.0).collect();
    lines.sort_unstable();
    lines.dedup();
    let mut prev: Option<usize> = None;
    for li in lines {
        if let Some(p) = prev {
            if li > p + 1 {
                out.push_str(&format!("{pad} ...\n"));
            }
        }
        prev = Some(li);
        let text: String = source
            .line_text(li)
            .chars()
            .map(|c| match c {
                '\t' => ' ',
                // invisible or terminal-garbling characters: one visible
                // column each, so the caret stays aligned
                c if super::lexer::invisible_name(c).is_some() => '\u{fffd}',
                c => c,
            })
            .collect();
        out.push_str(&format!("{:>gw$} | {}\n", li + 1, text.trim_end()));
        let mut on_line: Vec<_> = marks.iter().filter(|m| m.0 == li).collect();
        on_line.sort_by_key(|m| (!m.3, m.1));
        for m in on_line {
            let ch = if m.3 { "^" } else { "-" };
            let label = if m.4.is_empty() {
                String::new()
            } else {
                format!(" {}", m.4)
            };
            out.push_str(&format!(
                "{pad} | {}{}{}\n",
                " ".repeat(m.1),
                ch.repeat(m.2),
                label
            ));
        }
    }
    if let Some(h) = &d.help {
        out.push_str(&format!("{pad} = help: {h}\n"));
    }
}

/// (0-based line, 0-based char column, width in chars) of the first line of a span.
fn locate(source: &SourceFile, span: Span) -> (usize, usize, usize) {
    let s = source.clamp(span.start);
    let li = source.line_index(s);
    let ls = source.line_span(li);
    let s = s.min(ls.end).max(ls.start);
    let e = source.clamp(span.end).min(ls.end).max(s);
    let c0 = source.text[ls.start..s].chars().count();
    let w = source.text[s..e].chars().count().max(1);
    (li, c0, w)
}
