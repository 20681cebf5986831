//! Inlay hints: the derived unit of every `let`, of T, V and of each force.

use crate::analysis::{short_dim, Analysis};
use lsp_types::{InlayHint, InlayHintKind, InlayHintLabel, Range};
use plantc_derive::lang::units::Dim;
use plantc_derive::lang::Span;

/// Hints inside `range`: `: [unit]` after the declared name.
pub fn inlay_hints(a: &Analysis, range: Range) -> Vec<InlayHint> {
    let (lo, hi) = (a.doc.offset(range.start), a.doc.offset(range.end));
    let f = &a.file;
    let mut items: Vec<(Span, Dim, &str)> = Vec::new();
    for l in &f.lets {
        if let Some(d) = a.dim_of_name(&l.name.name) {
            items.push((l.name.span, d, "derived unit of this `let`"));
        }
    }
    for e in &f.kinetic {
        if let Some(d) = a.dim_of(&e.expr) {
            items.push((e.name.span, d, "unit of the kinetic energy"));
        }
    }
    for e in &f.potential {
        if let Some(d) = a.dim_of(&e.expr) {
            items.push((e.name.span, d, "unit of the potential energy"));
        }
    }
    for fo in &f.forces {
        // the checked tree has the effects expanded in `expr`
        if a.checked.model.is_some() {
            if let Some(d) = a.dim_of(&fo.expr) {
                items.push((fo.coordinate.span, d, "unit of the generalised force"));
            }
        }
    }
    items.sort_by_key(|(s, _, _)| s.start);
    items
        .into_iter()
        .filter(|(s, _, _)| s.end >= lo && s.end <= hi)
        .map(|(s, d, what)| InlayHint {
            position: a.doc.position(s.end),
            label: InlayHintLabel::String(format!(": [{}]", short_dim(d))),
            kind: Some(InlayHintKind::TYPE),
            text_edits: None,
            tooltip: Some(lsp_types::InlayHintTooltip::String(format!("{what}: {d}"))),
            padding_left: None,
            padding_right: Some(true),
            data: None,
        })
        .collect()
}
