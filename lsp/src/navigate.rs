//! Go to definition, find references and rename.

use crate::analysis::Analysis;
use lsp_types::{Location, PrepareRenameResponse, TextEdit, Uri, WorkspaceEdit};
use plantc_derive::lang::ast::RecordedStmt;
use plantc_derive::lang::edit::{rename_edits, EditError};
use plantc_derive::lang::visit::{Role, SymbolRef};
use plantc_derive::lang::Span;
use std::collections::HashMap;

/// Where the name at `offset` is declared.
pub fn definition(a: &Analysis, uri: &Uri, offset: usize) -> Option<Location> {
    let o = a.occurrence_at(offset)?;
    let d = a.declarations(&o.symbol).next()?;
    Some(Location::new(uri.clone(), a.doc.range(d.span)))
}

/// Every occurrence of the name at `offset` (with or without its declaration).
pub fn references(a: &Analysis, uri: &Uri, offset: usize, with_decl: bool) -> Vec<Location> {
    let Some(o) = a.occurrence_at(offset) else {
        return Vec::new();
    };
    a.occurrences
        .iter()
        .filter(|x| x.symbol == o.symbol && (with_decl || x.role != Role::Declaration))
        .map(|x| Location::new(uri.clone(), a.doc.range(x.span)))
        .collect()
}

fn renamable(s: &SymbolRef) -> bool {
    matches!(
        s,
        SymbolRef::Model(_)
            | SymbolRef::Gain(..)
            | SymbolRef::Block(_)
            | SymbolRef::Surface(..)
            | SymbolRef::Mode(..)
    )
}

/// The range and current text of a renamable name at `offset`.
pub fn prepare_rename(a: &Analysis, offset: usize) -> Option<PrepareRenameResponse> {
    let o = a.occurrence_at(offset)?;
    if !renamable(&o.symbol) {
        return None;
    }
    Some(PrepareRenameResponse::RangeWithPlaceholder {
        range: a.doc.range(o.span),
        placeholder: a.slice(o.span).to_string(),
    })
}

/// Renames the name at `offset` everywhere, through the lossless editor
/// (which refuses names that are taken or would break the file).
pub fn rename(
    a: &Analysis,
    uri: &Uri,
    offset: usize,
    new_name: &str,
) -> Result<WorkspaceEdit, String> {
    let o = a
        .occurrence_at(offset)
        .ok_or_else(|| "no name here to rename".to_string())?;
    let taken = |n: &str| match declared(a, n, &o.symbol) {
        Some((what, span)) => format!(
            "`{n}` is already taken: {what} `{n}` is declared on line {}; choose another name",
            a.doc.position(span.start).line + 1
        ),
        None => format!("`{n}` is already taken in this scope; choose another name"),
    };
    let edits = rename_edits(a.text(), &o.symbol, new_name).map_err(|e| match e {
        EditError::InvalidSource(_) => {
            "the file has syntax errors; fix them before renaming".to_string()
        }
        EditError::NameTaken(n) => taken(&n),
        // a name the lossless editor's check finds declared twice: a
        // recorded controller's own names are outside the rename scopes
        EditError::WouldBreak(_) if declared(a, new_name.trim(), &o.symbol).is_some() => {
            taken(new_name.trim())
        }
        other => other.to_string(),
    })?;
    let edits: Vec<TextEdit> = edits
        .into_iter()
        .map(|(s, t)| TextEdit {
            range: a.doc.range(s),
            new_text: t,
        })
        .collect();
    Ok(WorkspaceEdit {
        changes: Some(HashMap::from([(uri.clone(), edits)])),
        ..Default::default()
    })
}

/// What else declares `name` in the file (not `symbol` itself), and where:
/// a model name, a gain, a surface, a mode, a set or controller, or a
/// recorded controller's signal, gain or let.
fn declared(a: &Analysis, name: &str, symbol: &SymbolRef) -> Option<(&'static str, Span)> {
    let f = &a.file;
    let model_kind = |n: &str| {
        if f.coordinates.iter().any(|c| c.name.name == n) {
            "the coordinate"
        } else if f.inputs.iter().any(|c| c.name.name == n) {
            "the input"
        } else if f.parameters.iter().any(|c| c.name.name == n) {
            "the parameter"
        } else if f.lets.iter().any(|c| c.name.name == n) {
            "the let"
        } else if f.outputs.iter().any(|c| c.name.name == n) {
            "the output"
        } else {
            "the energy"
        }
    };
    let of = |s: &SymbolRef| -> Option<&'static str> {
        let (n, what) = match s {
            SymbolRef::Model(n) => (n, model_kind(n)),
            SymbolRef::Gain(_, n) => (n, "the gain"),
            SymbolRef::Surface(_, n) => (n, "the surface"),
            SymbolRef::Mode(_, n) => (n, "the mode"),
            SymbolRef::Block(n) => (n, "the set or controller"),
            _ => return None,
        };
        (n == name).then_some(what)
    };
    let found = a
        .occurrences
        .iter()
        .filter(|x| x.role == Role::Declaration && &x.symbol != symbol)
        .find_map(|x| of(&x.symbol).map(|w| (w, x.span)));
    found.or_else(|| {
        a.file.recorded.iter().find_map(|r| {
            r.body.iter().find_map(|st| {
                let (n, what) = match st {
                    RecordedStmt::Signal { name, .. } => (name, "the recorded controller's signal"),
                    RecordedStmt::Gain { name, .. } => (name, "the recorded controller's gain"),
                    RecordedStmt::Let { name, .. } => (name, "the recorded controller's let"),
                    _ => return None,
                };
                (n.name == name).then_some((what, n.span))
            })
        })
    })
}
