//! Document symbols (the outline).

use crate::analysis::Analysis;
use lsp_types::{DocumentSymbol, SymbolKind};
use plantc_derive::lang::ast::ControllerStmt;
use plantc_derive::lang::Span;

#[allow(deprecated)] // `DocumentSymbol::deprecated` must be written
fn sym(
    a: &Analysis,
    name: &str,
    detail: Option<String>,
    kind: SymbolKind,
    span: Span,
    sel: Span,
    children: Vec<DocumentSymbol>,
) -> DocumentSymbol {
    DocumentSymbol {
        name: name.to_string(),
        detail,
        kind,
        tags: None,
        deprecated: None,
        range: a.doc.range(span),
        selection_range: a.doc.range(sel),
        children: (!children.is_empty()).then_some(children),
    }
}

/// The declarations of the file in source order; sets and controllers with
/// their entries as children.
pub fn document_symbols(a: &Analysis) -> Vec<DocumentSymbol> {
    let f = &a.file;
    let doc = |d: &Option<plantc_derive::lang::ast::StrLit>| d.as_ref().map(|s| s.value.clone());
    let mut v: Vec<DocumentSymbol> = Vec::new();
    if let Some(m) = &f.model {
        v.push(sym(
            a,
            &m.name.name,
            doc(&m.title),
            SymbolKind::MODULE,
            m.span,
            m.name.span,
            vec![],
        ));
    }
    for c in &f.coordinates {
        v.push(sym(
            a,
            &c.name.name,
            doc(&c.doc),
            SymbolKind::VARIABLE,
            c.span,
            c.name.span,
            vec![],
        ));
    }
    for i in &f.inputs {
        v.push(sym(
            a,
            &i.name.name,
            doc(&i.doc),
            SymbolKind::EVENT,
            i.span,
            i.name.span,
            vec![],
        ));
    }
    for o in &f.outputs {
        v.push(sym(
            a,
            &o.name.name,
            Some("output".into()),
            SymbolKind::PROPERTY,
            o.span,
            o.name.span,
            vec![],
        ));
    }
    for p in &f.parameters {
        let detail = format!(
            "{}{}",
            p.value.text,
            p.unit
                .as_ref()
                .map_or(String::new(), |u| format!(" [{}]", u.text))
        );
        v.push(sym(
            a,
            &p.name.name,
            Some(detail),
            SymbolKind::CONSTANT,
            p.span,
            p.name.span,
            vec![],
        ));
    }
    for l in &f.lets {
        v.push(sym(
            a,
            &l.name.name,
            Some("let".into()),
            SymbolKind::VARIABLE,
            l.span,
            l.name.span,
            vec![],
        ));
    }
    for e in &f.kinetic {
        v.push(sym(
            a,
            &e.name.name,
            Some("kinetic energy".into()),
            SymbolKind::FUNCTION,
            e.span,
            e.name.span,
            vec![],
        ));
    }
    for e in &f.potential {
        v.push(sym(
            a,
            &e.name.name,
            Some("potential energy".into()),
            SymbolKind::FUNCTION,
            e.span,
            e.name.span,
            vec![],
        ));
    }
    for fo in &f.forces {
        let name = format!("force {}", fo.coordinate.name);
        v.push(sym(
            a,
            &name,
            None,
            SymbolKind::FIELD,
            fo.span,
            fo.coordinate.span,
            vec![],
        ));
    }
    for s in f.sensors.iter().chain(&f.actuators) {
        let name = format!("{} {}", s.kind.keyword(), s.target.name);
        v.push(sym(
            a,
            &name,
            s.effect_name().map(str::to_string),
            SymbolKind::FIELD,
            s.span,
            s.target.span,
            vec![],
        ));
    }
    for s in &f.sets {
        let children = s
            .entries
            .iter()
            .map(|e| {
                sym(
                    a,
                    &e.name.name,
                    Some(a.slice(e.value.span).to_string()),
                    SymbolKind::CONSTANT,
                    e.span,
                    e.name.span,
                    vec![],
                )
            })
            .collect();
        v.push(sym(
            a,
            &s.name.name,
            doc(&s.title),
            SymbolKind::NAMESPACE,
            s.span,
            s.name.span,
            children,
        ));
    }
    for c in &f.controllers {
        let children = c
            .body
            .iter()
            .filter_map(|st| match st {
                ControllerStmt::Gain { name, span, .. } => Some(sym(
                    a,
                    &name.name,
                    Some("gain".into()),
                    SymbolKind::CONSTANT,
                    *span,
                    name.span,
                    vec![],
                )),
                _ => None,
            })
            .collect();
        v.push(sym(
            a,
            &c.name.name,
            doc(&c.title),
            SymbolKind::CLASS,
            c.span,
            c.name.span,
            children,
        ));
    }
    v.sort_by_key(|s| (s.range.start.line, s.range.start.character));
    v
}
