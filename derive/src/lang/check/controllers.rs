//! Checks of `controller` blocks: one design per controller (pole placement,
//! LQR, given gains, feedback linearization, sliding mode, a direct law, or
//! modes with switches), the statements each design allows, the names its
//! laws and switch conditions use, and the units of the conditions.

use super::super::ast::*;
use super::super::diagnostic::Diagnostic;
use super::super::span::Span;
use super::super::units::Dim;
use super::{did_you_mean, suggest, Checker, Ctx, Infer, SymbolKind, BUILTINS};
use std::collections::BTreeMap;

/// Functions available in controller laws and switch conditions only:
/// `sat(x)` (clamp to [-1, 1]) and `energy(q)` (the energy of coordinate
/// `q`'s subsystem, zero at `q = 0` at rest; see [`crate::model::ControllerSpec`]).
pub const CONTROLLER_FUNCTIONS: &[(&str, usize)] = &[("sat", 1), ("energy", 1)];

/// The design a controller block declares.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Design {
    Place,
    Lqr,
    Gains,
    Linearize,
    Surface,
    Direct,
    Modes,
}

impl Design {
    fn of(s: &ControllerStmt, inputs: &[&str]) -> Option<Design> {
        match s {
            ControllerStmt::Place { .. } => Some(Design::Place),
            ControllerStmt::Lqr { .. } => Some(Design::Lqr),
            ControllerStmt::Gains { .. } => Some(Design::Gains),
            ControllerStmt::Linearize { .. } => Some(Design::Linearize),
            ControllerStmt::Surface { .. } => Some(Design::Surface),
            ControllerStmt::Mode { .. } => Some(Design::Modes),
            ControllerStmt::Law { target, .. } if inputs.contains(&target.name.as_str()) => {
                Some(Design::Direct)
            }
            _ => None,
        }
    }

    /// Gains and a law `v = ...` belong to these.
    fn has_outer_law(self) -> bool {
        matches!(self, Design::Linearize | Design::Surface)
    }
}

impl Infer<'_> {
    /// `sat(x)` and `energy(q)` in a switch condition; `None` for other functions.
    pub(super) fn controller_call(
        &mut self,
        e: &Expr,
        f: &Ident,
        args: &[Expr],
    ) -> Option<Option<Dim>> {
        let arity = CONTROLLER_FUNCTIONS
            .iter()
            .find(|(n, _)| *n == f.name)
            .map(|(_, a)| *a)?;
        if args.len() != arity {
            self.diags
                .push(super::wrong_arity(&f.name, arity, args.len(), e.span));
            return Some(None);
        }
        if f.name == "energy" {
            return Some(match energy_argument(&args[0], self.syms) {
                None => Some(Dim::energy()),
                Some(d) => {
                    self.diags.push(d);
                    None
                }
            });
        }
        let d = self.infer(&args[0])?;
        if !d.is_none() {
            self.diags.push(
                Diagnostic::error(
                    "plantc::unit_mismatch",
                    format!("`sat` needs a dimensionless argument, found {d}"),
                    args[0].span,
                    format!("expected 1 (dimensionless), found {d}"),
                )
                .with_help("divide by the saturation level, e.g. `Vmax*sat(x/Vmax)`"),
            );
            return Some(None);
        }
        Some(Some(Dim::NONE))
    }
}

/// The argument of `energy(q)` must be a coordinate's name: the error if not.
fn energy_argument(arg: &Expr, syms: &super::Symbols) -> Option<Diagnostic> {
    if let ExprKind::Name(n) = &arg.kind {
        if matches!(
            syms.names.get(n).map(|s| s.kind),
            Some(SymbolKind::Coordinate(_))
        ) {
            return None;
        }
    }
    let coords: Vec<&str> = syms
        .names
        .iter()
        .filter(|(_, s)| matches!(s.kind, SymbolKind::Coordinate(_)))
        .map(|(n, _)| n.as_str())
        .collect();
    Some(Diagnostic::error(
        "plantc::bad_energy",
        "`energy` takes a coordinate's name",
        arg.span,
        "not a coordinate",
    )
    .with_help(format!(
        "`energy(q)` is the kinetic energy with the other coordinates' velocities at 0 plus the potential energy minus its value at q = 0; coordinates: {}",
        coords.join(", ")
    )))
}

impl Checker {
    pub(super) fn check_controllers(&mut self, file: &ModelFile) {
        let n_states = 2 * file.coordinates.len();
        let n_inputs = file.inputs.len();
        let inputs: Vec<&str> = file.inputs.iter().map(|i| i.name.name.as_str()).collect();
        let hybrid: Vec<&str> = file
            .controllers
            .iter()
            .filter(|c| {
                c.body
                    .iter()
                    .any(|s| matches!(s, ControllerStmt::Mode { .. }))
            })
            .map(|c| c.name.name.as_str())
            .collect();
        for c in &file.controllers {
            let mut designs: Vec<(Design, Span)> = Vec::new();
            for s in &c.body {
                if let Some(d) = Design::of(s, &inputs) {
                    // several `mode` lines or direct laws are one design
                    if !(matches!(d, Design::Modes | Design::Direct)
                        && designs.iter().any(|(e, _)| *e == d))
                    {
                        designs.push((d, s.span()));
                    }
                }
            }
            let bad_law = c.body.iter().any(
                |s| matches!(s, ControllerStmt::Law { target, .. } if target.name != "v" && !inputs.contains(&target.name.as_str())),
            );
            if designs.is_empty() && !bad_law {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::controller_kind",
                        format!("controller `{}` has no design statement", c.name.name),
                        c.name.span,
                        "what kind of controller is this?",
                    )
                    .with_help("add one of `place poles [...]`, `lqr Q [...] R [...]`, `gains K [...]`, `linearize output y`, `surface s = ...`, a direct law `u = ...` for an input `u`, or `mode` lines"),
                );
            }
            for extra in designs.iter().skip(1) {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::controller_kind",
                        format!(
                            "controller `{}` has more than one design statement",
                            c.name.name
                        ),
                        extra.1,
                        "second design statement",
                    )
                    .with_label(designs[0].1, "first one")
                    .with_help("declare each design as its own controller; a hybrid controller's `mode` lines name them"),
                );
            }
            let design = designs.first().map(|d| d.0);
            let mut gains: BTreeMap<String, Span> = BTreeMap::new();
            let mut has_law = false;
            let mut surface: Option<&Ident> = None;
            let mut direct: BTreeMap<&str, Span> = BTreeMap::new();
            let mut modes: BTreeMap<&str, Span> = BTreeMap::new();
            let mut entered: Vec<&str> = Vec::new();
            let mut wrapped: BTreeMap<&str, Span> = BTreeMap::new();
            for s in &c.body {
                match s {
                    ControllerStmt::Place { poles, span } => {
                        self.check_poles(
                            poles,
                            *span,
                            n_states,
                            file,
                            "poles (two per coordinate)",
                        );
                    }
                    ControllerStmt::Lqr { q, r, span } => {
                        if q.len() != n_states || r.len() != n_inputs {
                            self.diags.push(Diagnostic::error(
                                "plantc::weight_count",
                                format!(
                                    "expected {n_states} state weights and {n_inputs} input weight(s), found {} and {}",
                                    q.len(),
                                    r.len()
                                ),
                                *span,
                                "wrong number of weights",
                            ).with_help("Q and R are the diagonals of the LQR weight matrices"));
                        }
                        for w in q
                            .iter()
                            .filter(|w| w.value().is_nan() || w.value() < 0.0)
                            .chain(r.iter().filter(|w| w.value().is_nan() || w.value() <= 0.0))
                        {
                            self.diags.push(Diagnostic::error(
                                "plantc::bad_weight",
                                "LQR weights must be >= 0 for Q and > 0 for R",
                                w.span,
                                "invalid weight",
                            ));
                        }
                    }
                    ControllerStmt::Gains { values, span, .. } => {
                        if values.len() != n_states * n_inputs {
                            self.diags.push(Diagnostic::error(
                                "plantc::gain_count",
                                format!("expected {} gains ({n_states} states x {n_inputs} inputs), found {}", n_states * n_inputs, values.len()),
                                *span,
                                "wrong number of gains",
                            ));
                        }
                    }
                    ControllerStmt::Linearize { output, .. } => {
                        if !file.outputs.iter().any(|o| o.name.name == output.name) {
                            let cands: Vec<&str> =
                                file.outputs.iter().map(|o| o.name.name.as_str()).collect();
                            let mut d = Diagnostic::error(
                                "plantc::unknown_output",
                                format!("`{}` is not a declared output", output.name),
                                output.span,
                                "not an output",
                            );
                            d.help = did_you_mean(&suggest(&output.name, cands))
                                .or(Some(format!("declare it with `output {}`", output.name)));
                            self.diags.push(d);
                        }
                    }
                    ControllerStmt::Gain { name, value, span } => {
                        if design.is_some_and(|d| {
                            !matches!(d, Design::Linearize | Design::Surface | Design::Direct)
                        }) {
                            self.diags.push(Diagnostic::error(
                                "plantc::controller_kind",
                                "`gain` lines belong to a `linearize output`, `surface` or direct-law controller",
                                *span,
                                "no law in this controller uses gains",
                            ));
                        }
                        if let Some(prev) = gains.get(&name.name) {
                            self.diags.push(
                                Diagnostic::error(
                                    "plantc::duplicate_definition",
                                    format!("gain `{}` is declared twice", name.name),
                                    name.span,
                                    "declared again here",
                                )
                                .with_label(*prev, "first declared here"),
                            );
                        }
                        gains.insert(name.name.clone(), name.span);
                        self.infer(value, Ctx::Constant);
                    }
                    ControllerStmt::Law { target, expr, span } => {
                        if inputs.contains(&target.name.as_str()) {
                            if let Some(prev) = direct.get(target.name.as_str()) {
                                self.diags.push(
                                    Diagnostic::error(
                                        "plantc::duplicate_definition",
                                        format!("two laws for input `{}`", target.name),
                                        target.span,
                                        "second law",
                                    )
                                    .with_label(*prev, "first law"),
                                );
                            }
                            direct.insert(&target.name, target.span);
                            self.check_law(expr, &gains, LawNames::Direct);
                            continue;
                        }
                        has_law = true;
                        if target.name != "v" {
                            let mut cands = vec!["v"];
                            cands.extend(inputs.iter().copied());
                            let mut d = Diagnostic::error(
                                "plantc::bad_law",
                                format!("unknown controller statement `{} = ...`", target.name),
                                target.span,
                                "expected `v` or an input",
                            );
                            d.help = did_you_mean(&suggest(&target.name, cands.iter().copied())).or(Some(format!(
                                "the outer law of feedback linearization or sliding mode is written `v = ...`; a direct law names an input: {}",
                                inputs.iter().map(|i| format!("`{i} = ...`")).collect::<Vec<_>>().join(", ")
                            )));
                            self.diags.push(d);
                            self.check_law(expr, &gains, LawNames::Direct);
                            continue;
                        }
                        match design {
                            Some(Design::Linearize) => {
                                self.check_law(expr, &gains, LawNames::Output)
                            }
                            Some(Design::Surface) => self.check_law(
                                expr,
                                &gains,
                                LawNames::Surface(surface.map_or("s", |s| s.name.as_str())),
                            ),
                            _ => self.diags.push(Diagnostic::error(
                                "plantc::controller_kind",
                                "a law `v = ...` belongs to a `linearize output` or `surface` controller",
                                *span,
                                "no `linearize output` or `surface` in this controller",
                            ).with_help(format!(
                                "to command an input directly, name it: {}",
                                inputs.iter().map(|i| format!("`{i} = ...`")).collect::<Vec<_>>().join(", ")
                            ))),
                        }
                    }
                    ControllerStmt::Surface { name, def, span } => {
                        surface = Some(name);
                        if n_inputs != 1 {
                            self.diags.push(Diagnostic::error(
                                "plantc::controller_kind",
                                format!("sliding mode is implemented for one input; the model has {n_inputs}"),
                                *span,
                                "needs a single-input model",
                            ));
                        }
                        if name.name == "y"
                            || gains.contains_key(&name.name)
                            || self.syms.names.contains_key(&name.name)
                        {
                            self.diags.push(Diagnostic::error(
                                "plantc::duplicate_definition",
                                format!("the surface name `{}` is already used", name.name),
                                name.span,
                                "choose another name",
                            ));
                        }
                        match def {
                            SurfaceDef::Poles(poles) => self.check_poles(
                                poles,
                                *span,
                                n_states.saturating_sub(1),
                                file,
                                "sliding-mode poles (one fewer than the states)",
                            ),
                            SurfaceDef::Expr(e) => self.check_law(e, &gains, LawNames::SurfaceDef),
                        }
                    }
                    ControllerStmt::Mode {
                        name,
                        controller,
                        span,
                        ..
                    } => {
                        if let Some(prev) = modes.get(name.name.as_str()) {
                            self.diags.push(
                                Diagnostic::error(
                                    "plantc::duplicate_definition",
                                    format!("mode `{}` is declared twice", name.name),
                                    name.span,
                                    "declared again here",
                                )
                                .with_label(*prev, "first declared here"),
                            );
                        }
                        if modes.is_empty() {
                            entered.push(&name.name);
                        }
                        modes.insert(&name.name, name.span);
                        let known: Vec<&str> = file
                            .controllers
                            .iter()
                            .map(|k| k.name.name.as_str())
                            .filter(|k| *k != c.name.name && !hybrid.contains(k))
                            .collect();
                        if controller.name == c.name.name
                            || hybrid.contains(&controller.name.as_str())
                        {
                            self.diags.push(
                                Diagnostic::error(
                                    "plantc::bad_mode",
                                    format!(
                                        "mode `{}` names the hybrid controller `{}`",
                                        name.name, controller.name
                                    ),
                                    controller.span,
                                    "modes cannot nest",
                                )
                                .with_help(format!(
                                    "a mode is driven by a controller without modes: {}",
                                    known.join(", ")
                                )),
                            );
                        } else if !file
                            .controllers
                            .iter()
                            .any(|k| k.name.name == controller.name)
                        {
                            let mut d = Diagnostic::error(
                                "plantc::unknown_controller",
                                format!("no controller `{}` in this file", controller.name),
                                controller.span,
                                "not a controller",
                            );
                            d.help =
                                did_you_mean(&suggest(&controller.name, known.iter().copied())).or(
                                    Some(format!("controllers of this file: {}", known.join(", "))),
                                );
                            self.diags.push(d);
                        }
                        let _ = span;
                    }
                    ControllerStmt::Switch {
                        from,
                        to,
                        when,
                        span,
                    } => {
                        if design != Some(Design::Modes) {
                            self.diags.push(Diagnostic::error(
                                "plantc::controller_kind",
                                "`switch` lines belong to a controller with `mode` lines",
                                *span,
                                "no modes in this controller",
                            ));
                        }
                        for m in [from, to] {
                            if !modes.contains_key(m.name.as_str()) {
                                let later = c.body.iter().any(|s| matches!(s, ControllerStmt::Mode { name, .. } if name.name == m.name));
                                let mut d = Diagnostic::error(
                                    "plantc::unknown_mode",
                                    format!("no mode `{}` declared before this line", m.name),
                                    m.span,
                                    "not a mode",
                                );
                                d.help = if later {
                                    Some(
                                        "declare the `mode` lines before the `switch` lines".into(),
                                    )
                                } else {
                                    did_you_mean(&suggest(&m.name, modes.keys().copied()))
                                        .or(Some("declare it with `mode name = controller`".into()))
                                };
                                self.diags.push(d);
                            }
                        }
                        if from.name == to.name {
                            self.diags.push(Diagnostic::error(
                                "plantc::bad_switch",
                                format!("switch from `{}` to itself", from.name),
                                to.span,
                                "same mode",
                            ));
                        }
                        entered.push(&to.name);
                        self.check_guard(when);
                    }
                    ControllerStmt::Wrap { coordinate, span } => {
                        if design != Some(Design::Modes) {
                            self.diags.push(Diagnostic::error(
                                "plantc::controller_kind",
                                "`wrap` lines belong to a controller with `mode` lines",
                                *span,
                                "no modes in this controller",
                            ).with_help("a hybrid controller's modes and switch conditions see the wrapped angle"));
                        }
                        match self.syms.names.get(&coordinate.name).map(|s| s.kind) {
                            Some(SymbolKind::Coordinate(CoordKind::Angle)) => {}
                            _ => {
                                let angles: Vec<&str> = file
                                    .coordinates
                                    .iter()
                                    .filter(|q| q.kind == CoordKind::Angle)
                                    .map(|q| q.name.name.as_str())
                                    .collect();
                                self.diags.push(
                                    Diagnostic::error(
                                        "plantc::bad_wrap",
                                        format!("`{}` is not an angle coordinate", coordinate.name),
                                        coordinate.span,
                                        "cannot wrap this",
                                    )
                                    .with_help(format!("angle coordinates: {}", angles.join(", "))),
                                );
                            }
                        }
                        if let Some(prev) = wrapped.insert(&coordinate.name, coordinate.span) {
                            self.diags.push(
                                Diagnostic::error(
                                    "plantc::duplicate_definition",
                                    format!("`{}` is wrapped twice", coordinate.name),
                                    coordinate.span,
                                    "again here",
                                )
                                .with_label(prev, "first here"),
                            );
                        }
                    }
                }
            }
            if design.is_some_and(Design::has_outer_law) && !has_law {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::missing_law",
                        format!("controller `{}` has no law `v = ...`", c.name.name),
                        c.name.span,
                        if design == Some(Design::Surface) {
                            "sliding mode needs a reaching law"
                        } else {
                            "feedback linearization needs an outer law"
                        },
                    )
                    .with_help(if design == Some(Design::Surface) {
                        "e.g. `v = -k*sat(s/phi)` (s' = v)"
                    } else {
                        "e.g. `v = -wn^2*y - 2*zeta*wn*y'`"
                    }),
                );
            }
            if design == Some(Design::Direct) {
                for i in &inputs {
                    if !direct.contains_key(i) {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::missing_law",
                                format!("controller `{}` has no law for input `{i}`", c.name.name),
                                c.name.span,
                                "a direct law commands every input",
                            )
                            .with_help(format!("add `{i} = ...`")),
                        );
                    }
                }
            }
            if design == Some(Design::Modes) {
                for s in &c.body {
                    if let ControllerStmt::Mode { name, .. } = s {
                        if !entered.contains(&name.name.as_str()) {
                            self.diags.push(
                                Diagnostic::warning(
                                    "plantc::unreachable_mode",
                                    format!("mode `{}` is never entered", name.name),
                                    name.span,
                                    "no switch leads here",
                                )
                                .with_help("the first mode is the initial one; add `switch other -> this when ...`"),
                            );
                        }
                    }
                }
            }
        }
    }

    fn check_poles(
        &mut self,
        poles: &[ComplexLit],
        span: Span,
        expected: usize,
        file: &ModelFile,
        what: &str,
    ) {
        if poles.len() != expected {
            self.diags.push(
                Diagnostic::error(
                    "plantc::pole_count",
                    format!("expected {expected} {what}, found {}", poles.len()),
                    span,
                    format!("{} poles", poles.len()),
                )
                .with_help(format!(
                    "the model has {} coordinate(s), so {} states",
                    file.coordinates.len(),
                    2 * file.coordinates.len()
                )),
            );
        }
        for p in poles {
            let (re, im) = p.value();
            if im != 0.0 && !poles.iter().any(|o| o.value() == (re, -im)) {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::pole_conjugate",
                        "a complex pole needs its conjugate in the list",
                        p.span,
                        "no conjugate partner",
                    )
                    .with_help("a real system's poles come in pairs `a+bi`, `a-bi`"),
                );
            }
        }
    }

    /// A switch condition: names, units of both sides of every comparison.
    fn check_guard(&mut self, g: &Guard) {
        for (op, a, b) in g.comparisons() {
            let da = self.infer(a, Ctx::Controller);
            let db = self.infer(b, Ctx::Controller);
            if let (Some(da), Some(db)) = (da, db) {
                if da != db {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::unit_mismatch",
                            format!("cannot compare {da} with {db}"),
                            b.span,
                            format!("this is {db}"),
                        )
                        .with_label(a.span, format!("this is {da}"))
                        .with_help(format!(
                            "both sides of `{}` must have the same unit, e.g. `abs(alpha) < 15 [deg]`",
                            op.symbol()
                        )),
                    );
                }
            }
        }
    }

    /// Law names: gains, coordinates (and derivatives), parameters, and
    /// per kind `y`, `y'` (feedback linearization) or the surface name.
    fn check_law(&mut self, e: &Expr, gains: &BTreeMap<String, Span>, kind: LawNames<'_>) {
        let mut errs = Vec::new();
        let extra: Vec<&str> = match kind {
            LawNames::Output => vec!["y"],
            LawNames::Surface(s) => vec![s],
            LawNames::Direct | LawNames::SurfaceDef => vec![],
        };
        let what = match kind {
            LawNames::Output => "a gain, `y`, a coordinate or a parameter",
            LawNames::Surface(_) => "a gain, the surface, a coordinate or a parameter",
            LawNames::Direct | LawNames::SurfaceDef => "a gain, a coordinate or a parameter",
        };
        e.walk(&mut |x| match &x.kind {
            ExprKind::Name(n) => {
                let ok = extra.contains(&n.as_str())
                    || gains.contains_key(n)
                    || matches!(
                        self.syms.names.get(n).map(|s| s.kind),
                        Some(SymbolKind::Coordinate(_)) | Some(SymbolKind::Parameter)
                    );
                if !ok {
                    let cands: Vec<&str> = gains
                        .keys()
                        .map(|s| s.as_str())
                        .chain(extra.iter().copied())
                        .chain(
                            self.syms
                                .names
                                .iter()
                                .filter(|(_, s)| matches!(s.kind, SymbolKind::Coordinate(_) | SymbolKind::Parameter))
                                .map(|(n, _)| n.as_str()),
                        )
                        .collect();
                    let place = if kind == LawNames::SurfaceDef { "surface" } else { "law" };
                    let mut d = Diagnostic::error("plantc::unknown_name", format!("unknown name `{n}` in the {place}"), x.span, format!("not {what}"));
                    d.help = did_you_mean(&suggest(n, cands)).or(Some("declare gains with `gain name = value`".into()));
                    errs.push(d);
                }
            }
            ExprKind::Deriv(n, k) => {
                let ok = (kind == LawNames::Output && n == "y" && *k == 1)
                    || matches!(self.syms.names.get(n).map(|s| s.kind), Some(SymbolKind::Coordinate(_)));
                if !ok {
                    errs.push(
                        Diagnostic::error("plantc::bad_derivative", format!("`{n}{}` is not available in the law", "'".repeat(*k as usize)), x.span, "not allowed here")
                            .with_help(if kind == LawNames::Output {
                                "the law may use `y`, `y'` (output and its derivative), coordinates and their derivatives"
                            } else {
                                "the law may use coordinates and their derivatives"
                            }),
                    );
                }
            }
            ExprKind::Call(f, args) => {
                if let Some((_, arity)) = CONTROLLER_FUNCTIONS.iter().find(|(b, _)| *b == f.name) {
                    if args.len() != *arity {
                        errs.push(super::wrong_arity(&f.name, arity, args.len(), x.span));
                    } else if f.name == "energy" {
                        if let Some(d) = energy_argument(&args[0], &self.syms) {
                            errs.push(d);
                        }
                    }
                } else if !BUILTINS.iter().any(|(b, _)| *b == f.name) {
                    let cands = BUILTINS.iter().chain(CONTROLLER_FUNCTIONS).map(|(n, _)| *n);
                    let mut d = Diagnostic::error("plantc::unknown_function", format!("unknown function `{}`", f.name), f.span, "not a built-in function");
                    d.help = did_you_mean(&suggest(&f.name, cands));
                    errs.push(d);
                }
            }
            _ => {}
        });
        self.diags.extend(errs);
    }
}

/// Which extra names a law may use.
#[derive(Clone, Copy, PartialEq, Eq)]
enum LawNames<'a> {
    /// `v = ...` of feedback linearization: `y`, `y'`.
    Output,
    /// `v = ...` of sliding mode: the surface.
    Surface(&'a str),
    /// `u = ...` for an input.
    Direct,
    /// The surface's own definition.
    SurfaceDef,
}
