//! What the server knows about one document: the checked model, the names
//! and their occurrences. Recomputed on every change (a few hundred
//! microseconds for the reference models).

use crate::document::Document;
use plantc_derive::lang::ast::{Expr, ExprKind, ModelFile};
use plantc_derive::lang::check::SymbolKind;
use plantc_derive::lang::units::Dim;
use plantc_derive::lang::visit::{occurrences, root_exprs, Occurrence, Role, SymbolRef};
use plantc_derive::lang::{dimension_of, parse_and_check, Checked, Span};

/// A document with its analysis.
#[derive(Debug, Clone)]
pub struct Analysis {
    /// The document.
    pub doc: Document,
    /// `check`'s result (diagnostics, and the tree when it parsed).
    pub checked: Checked,
    /// The tree: the checked one, or the parser's partial tree after syntax errors.
    pub file: ModelFile,
    /// Every written name.
    pub occurrences: Vec<Occurrence>,
}

impl Analysis {
    /// Parses and checks a document.
    pub fn new(doc: Document, name: &str) -> Analysis {
        let checked = parse_and_check(name, doc.text());
        let file = match &checked.model {
            Some(m) => m.clone(),
            None => plantc_derive::lang::parser::parse(doc.text()).0,
        };
        let occurrences = occurrences(&file);
        Analysis {
            doc,
            checked,
            file,
            occurrences,
        }
    }

    /// The text.
    pub fn text(&self) -> &str {
        self.doc.text()
    }

    /// The source under a span.
    pub fn slice(&self, span: Span) -> &str {
        let t = self.text();
        let s = span.start.min(t.len());
        let e = span.end.min(t.len()).max(s);
        t.get(s..e).unwrap_or("")
    }

    /// The name under (or just after) byte `offset`.
    pub fn occurrence_at(&self, offset: usize) -> Option<&Occurrence> {
        plantc_derive::lang::visit::occurrence_at(&self.occurrences, offset)
    }

    /// Declarations of a symbol.
    pub fn declarations<'a>(&'a self, s: &'a SymbolRef) -> impl Iterator<Item = &'a Occurrence> {
        self.occurrences
            .iter()
            .filter(move |o| &o.symbol == s && o.role == Role::Declaration)
    }

    /// The dimension of an expression, when the file checked far enough.
    pub fn dim_of(&self, e: &Expr) -> Option<Dim> {
        let syms = self.checked.symbols.as_ref()?;
        dimension_of(e, syms).ok()
    }

    /// The dimension of a model name.
    pub fn dim_of_name(&self, name: &str) -> Option<Dim> {
        self.checked.symbols.as_ref()?.dim(name)
    }

    /// The call expression whose name is at `span`.
    pub fn call_at(&self, span: Span) -> Option<(&str, &[Expr])> {
        let mut found = None;
        for (root, _) in root_exprs(&self.file) {
            root.walk(&mut |e| {
                if let ExprKind::Call(f, args) = &e.kind {
                    if f.span == span {
                        found = Some((f.name.as_str(), args.as_slice()));
                    }
                }
            });
        }
        found
    }

    /// Spans of the unit texts inside `[ ]` (declarations and quantity literals).
    pub fn unit_spans(&self) -> Vec<Span> {
        let mut spans = Vec::new();
        for p in &self.file.parameters {
            spans.extend(p.unit.as_ref().map(|u| u.span));
        }
        for i in &self.file.inputs {
            spans.extend(i.unit.as_ref().map(|u| u.span));
        }
        for (root, _) in root_exprs(&self.file) {
            root.walk(&mut |e| {
                if let ExprKind::Quantity(_, u) = &e.kind {
                    spans.push(u.span);
                }
            });
        }
        spans.sort_by_key(|s| s.start);
        spans
    }

    /// The model-level names declared in the file (from the tree, so also
    /// after syntax errors), with what they are.
    pub fn model_names(&self) -> Vec<(String, SymbolKind)> {
        let f = &self.file;
        let mut v = Vec::new();
        v.extend(
            f.coordinates
                .iter()
                .map(|c| (c.name.name.clone(), SymbolKind::Coordinate(c.kind))),
        );
        v.extend(
            f.inputs
                .iter()
                .map(|i| (i.name.name.clone(), SymbolKind::Input)),
        );
        v.extend(
            f.parameters
                .iter()
                .map(|p| (p.name.name.clone(), SymbolKind::Parameter)),
        );
        v.extend(
            f.lets
                .iter()
                .map(|l| (l.name.name.clone(), SymbolKind::Let)),
        );
        v
    }

    /// What a model name is, if declared.
    pub fn kind_of(&self, name: &str) -> Option<SymbolKind> {
        let f = &self.file;
        if let Some(c) = f.coordinates.iter().find(|c| c.name.name == name) {
            return Some(SymbolKind::Coordinate(c.kind));
        }
        if f.inputs.iter().any(|i| i.name.name == name) {
            return Some(SymbolKind::Input);
        }
        if f.parameters.iter().any(|p| p.name.name == name) {
            return Some(SymbolKind::Parameter);
        }
        if f.lets.iter().any(|l| l.name.name == name) {
            return Some(SymbolKind::Let);
        }
        if f.outputs
            .iter()
            .any(|o| o.name.name == name && o.expr.is_some())
        {
            return Some(SymbolKind::Output);
        }
        if f.kinetic
            .iter()
            .chain(&f.potential)
            .any(|e| e.name.name == name)
        {
            return Some(SymbolKind::Energy);
        }
        None
    }
}

/// A dimension as a short unit text: `N*m`, `kg*m^2`, `1`.
pub fn short_dim(d: Dim) -> String {
    if d.is_none() {
        "1".into()
    } else {
        d.common_name()
            .map_or_else(|| d.base_form(), |n| n.to_string())
    }
}
