//! `check`'s diagnostics as LSP diagnostics, and the quick fixes their help
//! lines name.

use crate::analysis::Analysis;
use lsp_types::{
    CodeAction, CodeActionKind, CodeActionOrCommand, Diagnostic, DiagnosticRelatedInformation,
    DiagnosticSeverity, Location, NumberOrString, Range, TextEdit, Uri, WorkspaceEdit,
};
use plantc_derive::lang::diagnostic::Severity;
use plantc_derive::lang::units::readings;
use plantc_derive::lang::Span;
use std::collections::HashMap;

/// Most diagnostics published for one document; beyond, one note says how
/// many more there are. `check` prints 200 in a terminal
/// ([`plantc_derive::lang::diagnostic::MAX_RENDERED`]); an editor's problem
/// list scrolls, so five times that. Each published diagnostic costs about
/// 50 us and 13 KB to build and send (measured: 40,000 on one line of `$`
/// took 2 s and 536 MB), so 1000 stay near 50 ms and 13 MB.
pub const MAX_PUBLISHED: usize = 1000;

/// The diagnostics of a document: the message of `check` unchanged, its
/// primary span as the range, secondary labels and the help line as related
/// information (the help also in `data.help`); the first [`MAX_PUBLISHED`],
/// then a note with the count of the others.
pub fn to_lsp(a: &Analysis, uri: &Uri) -> Vec<Diagnostic> {
    let all = &a.checked.diagnostics;
    let mut out: Vec<Diagnostic> = all
        .iter()
        .take(MAX_PUBLISHED)
        .map(|d| {
            let mut related: Vec<DiagnosticRelatedInformation> = Vec::new();
            if !d.label.is_empty() {
                related.push(DiagnosticRelatedInformation {
                    location: Location::new(uri.clone(), a.doc.range(d.primary)),
                    message: d.label.clone(),
                });
            }
            related.extend(d.secondary.iter().map(|l| DiagnosticRelatedInformation {
                location: Location::new(uri.clone(), a.doc.range(l.span)),
                message: l.text.clone(),
            }));
            if let Some(h) = &d.help {
                related.push(DiagnosticRelatedInformation {
                    location: Location::new(uri.clone(), a.doc.range(d.primary)),
                    message: format!("help: {h}"),
                });
            }
            Diagnostic {
                range: a.doc.range(d.primary),
                severity: Some(match d.severity {
                    Severity::Error => DiagnosticSeverity::ERROR,
                    Severity::Warning => DiagnosticSeverity::WARNING,
                    Severity::Note => DiagnosticSeverity::INFORMATION,
                }),
                code: Some(NumberOrString::String(d.code.to_string())),
                source: Some("plantc".into()),
                message: d.message.clone(),
                related_information: Some(related),
                data: d.help.as_ref().map(|h| serde_json::json!({ "help": h })),
                ..Default::default()
            }
        })
        .collect();
    if let Some(next) = all.get(MAX_PUBLISHED) {
        out.push(Diagnostic {
            range: a.doc.range(next.primary),
            severity: Some(DiagnosticSeverity::INFORMATION),
            source: Some("plantc".into()),
            message: format!(
                "{} more diagnostics not shown (the first {MAX_PUBLISHED} are listed; fix them first)",
                all.len() - MAX_PUBLISHED
            ),
            ..Default::default()
        });
    }
    out
}

/// The names a help line proposes: "did you mean `x`?" or "did you mean one
/// of `a`, `b`?".
pub fn proposed_names(help: &str) -> Vec<String> {
    let Some(i) = help.find("did you mean") else {
        return Vec::new();
    };
    let rest = &help[i..];
    let end = rest.find('?').unwrap_or(rest.len());
    rest[..end]
        .split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

fn is_name(s: &str) -> bool {
    let mut c = s.chars();
    c.next()
        .is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_')
}

fn is_number(s: &str) -> bool {
    !s.is_empty() && s.parse::<f64>().is_ok() && !s.contains(['[', ' '])
}

/// Quick fixes for the diagnostics that overlap `range`:
/// - a misspelt name (the help says "did you mean `x`?"): replace it;
/// - a number without its unit (the help names the unit): add it;
/// - an unknown unit: what it was meant to be, when that has one dimension
///   (`[kgm^2]` -> `[kg*m^2]`; see `units::readings`).
pub fn code_actions(a: &Analysis, uri: &Uri, range: Range) -> Vec<CodeActionOrCommand> {
    let (lo, hi) = (a.doc.offset(range.start), a.doc.offset(range.end));
    let lsp = to_lsp(a, uri);
    let mut out = Vec::new();
    for (d, ld) in a.checked.diagnostics.iter().zip(lsp) {
        if d.primary.end < lo || d.primary.start > hi {
            continue;
        }
        let here = a.slice(d.primary).to_string();
        let mut fixes: Vec<(String, Span, String)> = Vec::new();
        if let Some(help) = &d.help {
            if is_name(&here) {
                for n in proposed_names(help) {
                    if is_name(&n) {
                        fixes.push((format!("Replace `{here}` with `{n}`"), d.primary, n));
                    }
                }
            }
            // "write quantities with their unit in brackets, e.g. `1.0 [m]`"
            if d.code == "plantc::unit_mismatch" && is_number(&here) {
                if let Some(u) = help
                    .split_once("e.g. `")
                    .and_then(|(_, r)| r.split_once('`'))
                    .and_then(|(ex, _)| ex.split_once('['))
                    .and_then(|(_, u)| u.strip_suffix(']'))
                {
                    let at = Span::new(d.primary.end, d.primary.end);
                    fixes.push((format!("Add the unit `[{u}]`"), at, format!(" [{u}]")));
                }
            }
        }
        // only what the text meant, of one dimension (`units::readings`)
        if d.code == "plantc::unknown_unit" && is_name(&here) {
            for u in readings(&here) {
                fixes.push((format!("Replace unit `{here}` with `{u}`"), d.primary, u));
            }
        }
        for (i, (title, span, new_text)) in fixes.into_iter().enumerate() {
            let edit = TextEdit {
                range: a.doc.range(span),
                new_text,
            };
            out.push(CodeActionOrCommand::CodeAction(CodeAction {
                title,
                kind: Some(CodeActionKind::QUICKFIX),
                diagnostics: Some(vec![ld.clone()]),
                edit: Some(WorkspaceEdit {
                    changes: Some(HashMap::from([(uri.clone(), vec![edit])])),
                    ..Default::default()
                }),
                is_preferred: Some(i == 0),
                ..Default::default()
            }));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::proposed_names;

    #[test]
    fn names_from_help_lines() {
        assert_eq!(proposed_names("did you mean `theta`?"), vec!["theta"]);
        assert_eq!(
            proposed_names("did you mean one of `a`, `b`, `c`?"),
            vec!["a", "b", "c"]
        );
        assert_eq!(
            proposed_names("did you mean `input_offset`? effects valid in an `actuator` line: x"),
            vec!["input_offset"]
        );
        assert!(proposed_names("declare it with `parameter`").is_empty());
    }
}
