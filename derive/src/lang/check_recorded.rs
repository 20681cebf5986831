//! Checks of `recorded controller` blocks: the discrete-time law that drove
//! some inputs while data were recorded.
//!
//! A recorded controller sees what the rig's controller saw: the measured
//! coordinates (positions only: velocities come from `derivative(x, wc)`,
//! a filtered difference at the record's sample rate), the data columns it
//! declares with `signal`, its gains, its own `let`s, and the model's
//! parameters. Each law `u = expr` drives one model input and must have
//! that input's unit. Names are local to the block but may not shadow a
//! model name.

use std::collections::BTreeMap;

use super::{Checker, Ctx};
use crate::lang::ast::*;
use crate::lang::diagnostic::Diagnostic;
use crate::lang::span::Span;
use crate::lang::units::Dim;
use std::ops::Div;

use super::{Symbol, SymbolKind};

impl Checker {
    pub(super) fn check_recorded(&mut self, file: &ModelFile) {
        let mut block_names: BTreeMap<&str, Span> = BTreeMap::new();
        for c in &file.controllers {
            block_names.insert(&c.name.name, c.name.span);
        }
        for r in &file.recorded {
            if let Some(prev) = block_names.get(r.name.name.as_str()) {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::duplicate_definition",
                        format!("controller `{}` is declared twice", r.name.name),
                        r.name.span,
                        "declared again here",
                    )
                    .with_label(*prev, "first declared here")
                    .with_help("controllers and recorded controllers need distinct names"),
                );
            }
            block_names.insert(&r.name.name, r.name.span);
            self.check_recorded_block(r);
        }
    }

    fn check_recorded_block(&mut self, r: &RecordedController) {
        // the block's names go into a copy of the symbol table so that the
        // unit inference sees them; the model's table is restored afterwards
        let saved = self.syms.clone();
        let mut laws: BTreeMap<String, Span> = BTreeMap::new();
        for st in &r.body {
            match st {
                RecordedStmt::Signal { name, unit, .. } => {
                    let dim = self.resolve_unit(unit).map(|u| u.dim);
                    self.declare(name, SymbolKind::Let, dim);
                }
                RecordedStmt::Gain { name, value, .. } => {
                    let dim = self.infer(value, Ctx::Constant);
                    self.declare(name, SymbolKind::Parameter, dim);
                }
                RecordedStmt::Let { name, value, .. } => {
                    let dim = self.infer(value, Ctx::Recorded);
                    self.declare(name, SymbolKind::Let, dim);
                }
                RecordedStmt::Law { target, expr, span } => {
                    let dim = self.infer(expr, Ctx::Recorded);
                    let Some(unit) = self.syms.inputs.get(&target.name).copied() else {
                        let cands: Vec<&str> =
                            self.syms.inputs.keys().map(String::as_str).collect();
                        let mut d = Diagnostic::error(
                            "plantc::unknown_input",
                            format!("`{}` is not an input of the model", target.name),
                            target.span,
                            "not an input",
                        );
                        d.help = super::did_you_mean(&super::suggest(&target.name, cands))
                            .or(Some("a law `u = ...` drives one declared input".into()));
                        self.diags.push(d);
                        continue;
                    };
                    if let Some(prev) = laws.get(&target.name) {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::duplicate_law",
                                format!("input `{}` is driven twice", target.name),
                                *span,
                                "second law",
                            )
                            .with_label(*prev, "first law"),
                        );
                    }
                    laws.insert(target.name.clone(), *span);
                    if let Some(d) = dim {
                        if d != unit.dim {
                            self.diags.push(
                                Diagnostic::error(
                                    "plantc::unit_mismatch",
                                    format!(
                                        "the law for `{}` must be {}, found {d}",
                                        target.name, unit.dim
                                    ),
                                    expr.span,
                                    format!("this is {d}"),
                                )
                                .with_help(
                                    "give the gains their units, e.g. `gain kp = 6 [V/rad]`",
                                ),
                            );
                        }
                    }
                }
            }
        }
        if laws.is_empty() {
            self.diags.push(
                Diagnostic::error(
                    "plantc::missing_law",
                    format!("recorded controller `{}` drives no input", r.name.name),
                    r.name.span,
                    "no law `u = ...`",
                )
                .with_help(
                    "write the law it applied, e.g. `Vm = -kp*(target - theta) + feedforward`",
                ),
            );
        }
        self.syms = saved;
    }
}

impl super::Infer<'_> {
    /// `derivative(x, wc)` in a recorded controller: the filtered difference
    /// `wc s/(s + wc)` of `x`, discretised at the record's sample period;
    /// `wc` is a rate (1/s or rad/s). Its unit is x's per second.
    pub(super) fn derivative_call(&mut self, e: &Expr, args: &[Expr]) -> Option<Dim> {
        if args.len() != 2 {
            self.diags.push(
                Diagnostic::error(
                    "plantc::wrong_arity",
                    format!("`derivative` takes 2 arguments, found {}", args.len()),
                    e.span,
                    "wrong number of arguments",
                )
                .with_help("`derivative(x, wc)`: filtered derivative of x with cutoff wc, e.g. `derivative(theta, 50 [rad/s])`"),
            );
            return None;
        }
        let mut nested = None;
        args[0].walk(&mut |x| {
            if let ExprKind::Call(f, _) = &x.kind {
                if f.name == "derivative" && nested.is_none() {
                    nested = Some(x.span);
                }
            }
        });
        if let Some(span) = nested {
            self.diags.push(
                Diagnostic::error(
                    "plantc::nested_derivative",
                    "a filtered derivative cannot contain another one",
                    span,
                    "nested here",
                )
                .with_help("name the inner one with `let` only if the rig's code did the same; plantc supports one filter stage"),
            );
            return None;
        }
        let dx = self.infer(&args[0]);
        let dw = self.infer_constant(&args[1]);
        let rate = Dim::NONE.div(Dim::time());
        if let Some(dw) = dw {
            if dw != rate {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::unit_mismatch",
                        format!("the cutoff of `derivative` must be a rate (1/s), found {dw}"),
                        args[1].span,
                        format!("this is {dw}"),
                    )
                    .with_help("e.g. `derivative(theta, 50 [rad/s])`"),
                );
                return None;
            }
        }
        Some(dx?.div(Dim::time()))
    }

    /// The dimension of an expression that must be constant (parameters,
    /// gains, numbers).
    fn infer_constant(&mut self, e: &Expr) -> Option<Dim> {
        let ctx = self.ctx;
        self.ctx = Ctx::Constant;
        let d = self.infer(e);
        self.ctx = ctx;
        d
    }
}

/// Whether a symbol kind may be read by a recorded controller's law.
pub(super) fn readable_in_recorded(s: &Symbol) -> bool {
    !matches!(s.kind, SymbolKind::Input)
}
