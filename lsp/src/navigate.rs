//! Go to definition, find references and rename.

use crate::analysis::Analysis;
use lsp_types::{Location, PrepareRenameResponse, TextEdit, Uri, WorkspaceEdit};
use plantc_derive::lang::edit::{rename_edits, EditError};
use plantc_derive::lang::visit::{Role, SymbolRef};
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
        SymbolRef::Model(_) | SymbolRef::Gain(..) | SymbolRef::Block(_)
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
    let edits = rename_edits(a.text(), &o.symbol, new_name).map_err(|e| match e {
        EditError::InvalidSource(_) => {
            "the file has syntax errors; fix them before renaming".to_string()
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
