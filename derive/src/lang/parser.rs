//! Recursive-descent parser with error recovery.
//!
//! After an error the parser skips to the end of the statement (the next line
//! that does not continue it) and goes on, so one run reports several errors.

use super::ast::*;
use super::diagnostic::Diagnostic;
use super::lexer::{lex, Tok, Token};
use super::span::Span;

/// Maximum nesting of expressions (guards the stack on hostile input).
const MAX_DEPTH: usize = 200;

/// Chains of `+`/`-` (or `*`/`/`) with more operands than this become a
/// balanced tree instead of a left-deep one, so a 100,000-term sum is about
/// 20 levels deep for every recursive pass (checking, lowering, printing,
/// dropping) rather than 100,000. Shorter chains keep the usual left-deep
/// shape.
const CHAIN_BALANCE: usize = 32;

/// Maximum height of an expression tree (parentheses, chains, calls and
/// powers together): what the recursive passes after parsing may meet.
pub const MAX_HEIGHT: usize = 400;

/// The statement keywords.
pub const KEYWORDS: &[&str] = &[
    "model",
    "coordinate",
    "input",
    "output",
    "parameter",
    "let",
    "kinetic",
    "potential",
    "force",
    "sensor",
    "actuator",
    "inertia",
    "set",
    "controller",
    "recorded",
];

/// Parses a whole file. Always returns a (possibly partial) tree; syntax
/// errors are in the diagnostics.
pub fn parse(text: &str) -> (ModelFile, Vec<Diagnostic>) {
    let mut diags = Vec::new();
    let toks = lex(text, &mut diags);
    let mut p = Parser::new(text, toks, diags);
    let file = p.file();
    (file, p.diags)
}

/// Parses a single expression (newlines are ignored). Used for effect formulas.
pub fn parse_expr(text: &str) -> Result<Expr, Vec<Diagnostic>> {
    let mut diags = Vec::new();
    let toks = lex(text, &mut diags);
    let mut p = Parser::new(text, toks, diags);
    p.nl_depth = 1;
    let e = p.expr();
    if let Ok(e) = &e {
        if p.peek() != &Tok::Eof {
            let _ = p.unexpected::<()>("end of expression");
        }
        if p.diags.is_empty() {
            return Ok(e.clone());
        }
    }
    Err(p.diags)
}

type PResult<T> = Result<T, ()>;

struct Parser<'a> {
    src: &'a str,
    toks: Vec<Token>,
    pos: usize,
    nl_depth: usize,
    cont_indent: Option<usize>,
    depth: usize,
    diags: Vec<Diagnostic>,
}

impl<'a> Parser<'a> {
    fn new(src: &'a str, toks: Vec<Token>, diags: Vec<Diagnostic>) -> Parser<'a> {
        Parser {
            src,
            toks,
            pos: 0,
            nl_depth: 0,
            cont_indent: None,
            depth: 0,
            diags,
        }
    }

    // ---- token helpers ----

    fn skip_nl_if_nested(&mut self) {
        if self.nl_depth > 0 {
            while self.toks[self.pos].tok == Tok::Newline {
                self.pos += 1;
            }
        }
    }

    fn peek(&mut self) -> &Tok {
        self.skip_nl_if_nested();
        &self.toks[self.pos].tok
    }

    fn peek_token(&mut self) -> Token {
        self.skip_nl_if_nested();
        self.toks[self.pos].clone()
    }

    fn peek2(&mut self) -> Tok {
        self.skip_nl_if_nested();
        let mut j = self.pos + 1;
        if self.nl_depth > 0 {
            while j < self.toks.len() && self.toks[j].tok == Tok::Newline {
                j += 1;
            }
        }
        self.toks.get(j).map_or(Tok::Eof, |t| t.tok.clone())
    }

    fn bump(&mut self) -> Token {
        self.skip_nl_if_nested();
        let t = self.toks[self.pos].clone();
        if t.tok != Tok::Eof {
            self.pos += 1;
        }
        t
    }

    fn prev_end(&self) -> usize {
        if self.pos == 0 {
            0
        } else {
            self.toks[self.pos - 1].span.end
        }
    }

    fn skip_newlines(&mut self) {
        while self.toks[self.pos].tok == Tok::Newline {
            self.pos += 1;
        }
    }

    fn text(&self, span: Span) -> &'a str {
        &self.src[span.start..span.end]
    }

    fn is_kw(&mut self, kw: &str) -> bool {
        let t = self.peek_token();
        t.tok == Tok::Ident && self.text(t.span) == kw
    }

    fn found(&self, t: &Token) -> String {
        match t.tok {
            Tok::Ident | Tok::Number | Tok::Imag => format!("`{}`", self.text(t.span)),
            _ => t.tok.describe().to_string(),
        }
    }

    fn error(&mut self, d: Diagnostic) {
        self.diags.push(d);
    }

    fn unexpected<T>(&mut self, expected: &str) -> PResult<T> {
        let t = self.peek_token();
        let found = self.found(&t);
        let mut d = Diagnostic::error(
            "plantc::syntax",
            format!("expected {expected}, found {found}"),
            t.span,
            format!("expected {expected}"),
        );
        if t.tok == Tok::Newline || t.tok == Tok::Eof {
            let mut at = t.span.start;
            if t.tok == Tok::Eof {
                let trimmed = self.src.trim_end_matches(['\n', '\r']);
                if trimmed.len() < self.src.len() {
                    at = trimmed.len();
                }
            }
            d.primary = Span::new(at, at);
            d = d.with_help(
                "a statement ends at the end of its line; to continue it, end the line with an operator or `=`, or keep brackets open",
            );
        }
        self.error(d);
        Err(())
    }

    fn expect(&mut self, tok: Tok, what: &str) -> PResult<Token> {
        if *self.peek() == tok {
            Ok(self.bump())
        } else {
            self.unexpected(what)
        }
    }

    fn ident(&mut self, what: &str) -> PResult<Ident> {
        if *self.peek() == Tok::Ident {
            let t = self.bump();
            Ok(Ident {
                name: self.text(t.span).to_string(),
                span: t.span,
            })
        } else {
            self.unexpected(what)
        }
    }

    fn keyword(&mut self, kw: &str) -> PResult<Span> {
        if self.is_kw(kw) {
            Ok(self.bump().span)
        } else {
            self.unexpected(&format!("`{kw}`"))
        }
    }

    fn opt_str(&mut self) -> Option<StrLit> {
        let t = self.peek_token();
        if let Tok::Str(v) = t.tok {
            self.bump();
            Some(StrLit {
                value: v,
                span: t.span,
            })
        } else {
            None
        }
    }

    fn column(&self, offset: usize) -> usize {
        let line_start = self.src[..offset].rfind(['\n', '\r']).map_or(0, |i| i + 1);
        offset - line_start
    }

    // ---- recovery ----

    /// Skips to the end of the current statement: the next newline outside
    /// brackets, then any following lines that cannot start a statement.
    fn recover(&mut self, in_block: bool) {
        self.nl_depth = 0;
        self.cont_indent = None;
        let mut depth = 0usize;
        loop {
            let t = self.toks[self.pos].tok.clone();
            match t {
                Tok::Eof => return,
                Tok::RBrace if in_block && depth == 0 => return,
                Tok::Newline if depth == 0 => {
                    self.skip_newlines();
                    match self.toks[self.pos].tok {
                        Tok::Ident | Tok::Eof | Tok::RBrace => return,
                        _ => continue,
                    }
                }
                Tok::LParen | Tok::LBracket | Tok::LBrace => depth += 1,
                Tok::RParen | Tok::RBracket | Tok::RBrace => depth = depth.saturating_sub(1),
                _ => {}
            }
            self.pos += 1;
        }
    }

    fn end_of_statement(&mut self, in_block: bool) -> PResult<()> {
        match self.toks[self.pos].tok {
            Tok::Newline | Tok::Eof => Ok(()),
            Tok::RBrace if in_block => Ok(()),
            _ => self.unexpected("end of line"),
        }
    }

    // ---- file and statements ----

    fn file(&mut self) -> ModelFile {
        let mut file = ModelFile::default();
        loop {
            self.skip_newlines();
            let t = self.toks[self.pos].clone();
            if t.tok == Tok::Eof {
                break;
            }
            let r = self
                .statement(&mut file)
                .and_then(|_| self.end_of_statement(false));
            if r.is_err() {
                self.recover(false);
            }
            self.nl_depth = 0;
            self.cont_indent = None;
        }
        file
    }

    fn statement(&mut self, file: &mut ModelFile) -> PResult<()> {
        let t = self.peek_token();
        let kw = if t.tok == Tok::Ident {
            self.text(t.span)
        } else {
            ""
        };
        let start = t.span.start;
        match kw {
            "model" => {
                self.bump();
                let name = self.ident("a model name")?;
                let title = self.opt_str();
                if let Some(first) = &file.model {
                    let first = first.span;
                    self.error(
                        Diagnostic::error(
                            "plantc::duplicate_definition",
                            "a file declares one model",
                            Span::new(start, self.prev_end()),
                            "second `model` line",
                        )
                        .with_label(first, "first `model` line")
                        .with_help("put each model in its own file"),
                    );
                    return Err(());
                }
                file.model = Some(ModelDecl {
                    name,
                    title,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "coordinate" => {
                self.bump();
                let name = self.ident("a coordinate name")?;
                self.expect(Tok::Colon, "`:` and a kind (`angle` or `length`)")?;
                let k = self.ident("`angle` or `length`")?;
                let kind = match k.name.as_str() {
                    "angle" => CoordKind::Angle,
                    "length" => CoordKind::Length,
                    other => {
                        self.error(
                            Diagnostic::error(
                                "plantc::unknown_coordinate_kind",
                                format!("unknown coordinate kind `{other}`"),
                                k.span,
                                "not a coordinate kind",
                            )
                            .with_help("use `angle` (unit rad) or `length` (unit m)"),
                        );
                        CoordKind::Angle
                    }
                };
                let doc = self.opt_str();
                file.coordinates.push(Coordinate {
                    name,
                    kind,
                    kind_span: k.span,
                    doc,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "input" => {
                self.bump();
                let name = self.ident("an input name")?;
                let unit = if *self.peek() == Tok::LBracket {
                    Some(self.unit()?)
                } else {
                    None
                };
                let mut limits = None;
                let mut doc = None;
                loop {
                    if self.is_kw("limits") && limits.is_none() {
                        self.bump();
                        limits = Some(self.bounds()?);
                    } else if matches!(self.peek(), Tok::Str(_)) && doc.is_none() {
                        doc = self.opt_str();
                    } else {
                        break;
                    }
                }
                file.inputs.push(Input {
                    name,
                    unit,
                    limits,
                    doc,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "output" => {
                self.bump();
                let name = self.ident("an output name")?;
                let expr = if *self.peek() == Tok::Eq {
                    self.bump();
                    self.skip_newlines();
                    Some(self.statement_expr(start)?)
                } else {
                    None
                };
                let doc = self.opt_str();
                file.outputs.push(Output {
                    name,
                    expr,
                    doc,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "parameter" => {
                self.bump();
                let name = self.ident("a parameter name")?;
                self.expect(Tok::Eq, "`=` and a value")?;
                self.skip_newlines();
                let value = match self.signed_num() {
                    Ok(v) => v,
                    Err(()) => {
                        if let Some(d) = self.diags.last_mut() {
                            d.help = Some(
                                "a parameter's value is a number literal with an optional unit, e.g. `0.257 [kg]`; use `let` for values computed from other parameters".into(),
                            );
                        }
                        return Err(());
                    }
                };
                let unit = if *self.peek() == Tok::LBracket {
                    Some(self.unit()?)
                } else {
                    None
                };
                let mut estimate = None;
                let mut doc = None;
                loop {
                    if self.is_kw("estimate") && estimate.is_none() {
                        self.bump();
                        estimate = Some(self.bounds()?);
                    } else if matches!(self.peek(), Tok::Str(_)) && doc.is_none() {
                        doc = self.opt_str();
                    } else {
                        break;
                    }
                }
                file.parameters.push(Parameter {
                    name,
                    value,
                    unit,
                    doc,
                    estimate,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "let" => {
                self.bump();
                let name = self.ident("a name")?;
                self.expect(Tok::Eq, "`=`")?;
                self.skip_newlines();
                let expr = self.statement_expr(start)?;
                file.lets.push(Let {
                    name,
                    expr,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "kinetic" | "potential" => {
                self.bump();
                let name = self.ident("a name for the energy (e.g. `T`)")?;
                self.expect(Tok::Eq, "`=`")?;
                self.skip_newlines();
                let expr = self.statement_expr(start)?;
                let e = Energy {
                    name,
                    expr,
                    span: Span::new(start, self.prev_end()),
                };
                if kw == "kinetic" {
                    file.kinetic.push(e);
                } else {
                    file.potential.push(e);
                }
            }
            "force" => {
                self.bump();
                let coordinate = self.ident("a coordinate name")?;
                self.expect(Tok::Eq, "`=`")?;
                self.skip_newlines();
                let expr = self.statement_expr(start)?;
                file.forces.push(Force {
                    coordinate,
                    written: expr.clone(),
                    expr_end: expr.span.end,
                    expr,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "sensor" | "actuator" | "inertia" => {
                use super::effects::EffectKind;
                self.bump();
                let target = if kw == "actuator" {
                    self.ident("an input name")?
                } else {
                    self.ident("a coordinate name")?
                };
                self.expect(Tok::Eq, "`=`")?;
                self.skip_newlines();
                let call = self.expr()?;
                let kind = match kw {
                    "sensor" => EffectKind::Sensor,
                    "actuator" => EffectKind::Actuator,
                    _ => EffectKind::Inertia,
                };
                let line = SignalEffect {
                    kind,
                    target,
                    call,
                    span: Span::new(start, self.prev_end()),
                };
                match kind {
                    EffectKind::Sensor => file.sensors.push(line),
                    EffectKind::Actuator => file.actuators.push(line),
                    _ => file.inertias.push(line),
                }
            }
            "set" => {
                self.bump();
                let name = self.ident("a set name")?;
                let title = self.opt_str();
                let open = self.expect(Tok::LBrace, "`{`")?;
                let mut entries = Vec::new();
                self.block(open.span, |p| {
                    let name = p.ident("a parameter name")?;
                    p.expect(Tok::Eq, "`=`")?;
                    p.skip_newlines();
                    let value = p.expr()?;
                    entries.push(SetEntry {
                        span: name.span.to(value.span),
                        name,
                        value,
                    });
                    Ok(())
                })?;
                file.sets.push(ParamSet {
                    name,
                    title,
                    entries,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "controller" => {
                self.bump();
                let name = self.ident("a controller name")?;
                let title = self.opt_str();
                let open = self.expect(Tok::LBrace, "`{`")?;
                let mut body = Vec::new();
                self.block(open.span, |p| {
                    body.push(p.controller_stmt()?);
                    Ok(())
                })?;
                file.controllers.push(Controller {
                    name,
                    title,
                    body,
                    span: Span::new(start, self.prev_end()),
                });
            }
            "recorded" => {
                self.bump();
                self.keyword("controller")?;
                let name = self.ident("a controller name")?;
                let title = self.opt_str();
                let open = self.expect(Tok::LBrace, "`{`")?;
                let mut body = Vec::new();
                self.block(open.span, |p| {
                    body.push(p.recorded_stmt()?);
                    Ok(())
                })?;
                file.recorded.push(RecordedController {
                    name,
                    title,
                    body,
                    span: Span::new(start, self.prev_end()),
                });
            }
            _ => {
                let found = self.found(&t);
                let mut d = Diagnostic::error(
                    "plantc::syntax",
                    format!("expected a declaration, found {found}"),
                    t.span,
                    "not a declaration",
                )
                .with_help(format!(
                    "a line starts with one of: {}",
                    KEYWORDS.join(", ")
                ));
                if t.tok == Tok::Ident {
                    if let Some(s) = super::check::suggest(kw, KEYWORDS.iter().copied()).first() {
                        d = d.with_help(format!("did you mean `{s}`?"));
                    }
                }
                self.error(d);
                return Err(());
            }
        }
        Ok(())
    }

    /// Parses `{ item (newline item)* }`; each item is parsed by `item`.
    fn block(&mut self, open: Span, mut item: impl FnMut(&mut Self) -> PResult<()>) -> PResult<()> {
        loop {
            self.skip_newlines();
            match self.toks[self.pos].tok {
                Tok::RBrace => {
                    self.bump();
                    return Ok(());
                }
                Tok::Eof => {
                    let eof = self.toks[self.pos].span;
                    self.error(
                        Diagnostic::error(
                            "plantc::unclosed_block",
                            "unclosed `{`",
                            open,
                            "this block is never closed",
                        )
                        .with_label(eof, "file ends here")
                        .with_help("add `}` after the block's last line"),
                    );
                    return Err(());
                }
                _ => {}
            }
            let r = item(self).and_then(|_| self.end_of_statement(true));
            if r.is_err() {
                self.recover(true);
            }
            self.nl_depth = 0;
            self.cont_indent = None;
        }
    }

    fn controller_stmt(&mut self) -> PResult<ControllerStmt> {
        let t = self.peek_token();
        let start = t.span.start;
        let kw = if t.tok == Tok::Ident {
            self.text(t.span)
        } else {
            ""
        };
        let stmt = match kw {
            "place" => {
                self.bump();
                self.keyword("poles")?;
                let poles = self.list(|p| p.complex())?;
                ControllerStmt::Place {
                    poles,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "lqr" => {
                self.bump();
                self.keyword("Q")?;
                let q = self.list(|p| p.signed_num())?;
                self.keyword("R")?;
                let r = self.list(|p| p.signed_num())?;
                ControllerStmt::Lqr {
                    q,
                    r,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "gains" => {
                self.bump();
                let name = self.ident("a gain name (e.g. `K`)")?;
                let values = self.list(|p| p.signed_num())?;
                ControllerStmt::Gains {
                    name,
                    values,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "linearize" => {
                self.bump();
                self.keyword("output")?;
                let output = self.ident("an output name")?;
                ControllerStmt::Linearize {
                    output,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "gain" => {
                self.bump();
                let name = self.ident("a gain name")?;
                self.expect(Tok::Eq, "`=`")?;
                self.skip_newlines();
                let value = self.expr()?;
                ControllerStmt::Gain {
                    name,
                    value,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "surface" if self.peek2() == Tok::Ident => {
                self.bump();
                let name = self.ident("a surface name (e.g. `s`)")?;
                let def = if self.is_kw("poles") {
                    self.bump();
                    SurfaceDef::Poles(self.list(|p| p.complex())?)
                } else {
                    self.expect(Tok::Eq, "`=` and the surface, or `poles [...]`")?;
                    self.skip_newlines();
                    SurfaceDef::Expr(self.statement_expr(start)?)
                };
                ControllerStmt::Surface {
                    name,
                    def,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "mode" if self.peek2() == Tok::Ident => {
                self.bump();
                let name = self.ident("a mode name")?;
                self.expect(Tok::Eq, "`=` and the controller of this mode")?;
                let controller = self.ident("the name of a controller of this file")?;
                let swing_up = if self.is_kw("swing_up") {
                    Some(self.bump().span)
                } else {
                    None
                };
                ControllerStmt::Mode {
                    name,
                    controller,
                    swing_up,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "switch" if self.peek2() == Tok::Ident => {
                self.bump();
                let from = self.ident("the mode switched from")?;
                self.expect(Tok::Arrow, "`->`")?;
                let to = self.ident("the mode switched to")?;
                self.keyword("when")?;
                let when = self.guard()?;
                ControllerStmt::Switch {
                    from,
                    to,
                    when,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "wrap" if self.peek2() == Tok::Ident => {
                self.bump();
                let coordinate = self.ident("an angle coordinate")?;
                ControllerStmt::Wrap {
                    coordinate,
                    span: Span::new(start, self.prev_end()),
                }
            }
            _ if t.tok == Tok::Ident && self.peek2() == Tok::Eq => {
                let target = self.ident("a name")?;
                self.bump();
                self.skip_newlines();
                let expr = self.statement_expr(start)?;
                ControllerStmt::Law {
                    target,
                    expr,
                    span: Span::new(start, self.prev_end()),
                }
            }
            _ => {
                let found = self.found(&t);
                self.error(
                    Diagnostic::error(
                        "plantc::unknown_controller_statement",
                        format!("expected a controller statement, found {found}"),
                        t.span,
                        "not a controller statement",
                    )
                    .with_help(
                        "a controller is `place poles [...]`, `lqr Q [...] R [...]`, `gains K [...]`, `linearize output y` or `surface s = ...` with `gain name = value` lines and a law `v = ...`, a direct law `u = ...` for an input `u`, or `mode` and `switch` lines",
                    ),
                );
                return Err(());
            }
        };
        Ok(stmt)
    }

    /// `cmp (and cmp)* (or cmp (and cmp)*)*`.
    fn guard(&mut self) -> PResult<Guard> {
        self.guard_chain("or", GuardKind::Or, |p| {
            p.guard_chain("and", GuardKind::And, Self::comparison)
        })
    }

    /// `operand (keyword operand)*`, grouped to the left.
    fn guard_chain(
        &mut self,
        keyword: &str,
        join: fn(Box<Guard>, Box<Guard>) -> GuardKind,
        mut operand: impl FnMut(&mut Self) -> PResult<Guard>,
    ) -> PResult<Guard> {
        let mut lhs = operand(self)?;
        while self.is_kw(keyword) {
            self.bump();
            let rhs = operand(self)?;
            let span = lhs.span.to(rhs.span);
            lhs = Guard {
                kind: join(Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Ok(lhs)
    }

    fn comparison(&mut self) -> PResult<Guard> {
        let a = self.expr()?;
        let op = match self.peek() {
            Tok::Lt => CmpOp::Lt,
            Tok::Le => CmpOp::Le,
            Tok::Gt => CmpOp::Gt,
            Tok::Ge => CmpOp::Ge,
            _ => {
                let r = self.unexpected("a comparison `<`, `<=`, `>` or `>=`");
                if let Some(d) = self.diags.last_mut() {
                    d.help = Some(
                        "a switch condition compares two expressions, e.g. `when abs(alpha) < 15 [deg]`; join comparisons with `and` / `or`".into(),
                    );
                }
                return r;
            }
        };
        self.bump();
        let b = self.expr()?;
        let span = a.span.to(b.span);
        Ok(Guard {
            kind: GuardKind::Cmp(op, Box::new(a), Box::new(b)),
            span,
        })
    }

    fn recorded_stmt(&mut self) -> PResult<RecordedStmt> {
        let t = self.peek_token();
        let start = t.span.start;
        let kw = if t.tok == Tok::Ident {
            self.text(t.span)
        } else {
            ""
        };
        let stmt = match kw {
            "signal" if self.peek2() == Tok::Ident => {
                self.bump();
                let name = self.ident("a column name")?;
                let unit = if *self.peek() == Tok::LBracket {
                    Some(self.unit()?)
                } else {
                    None
                };
                let title = self.opt_str();
                RecordedStmt::Signal {
                    name,
                    unit,
                    title,
                    span: Span::new(start, self.prev_end()),
                }
            }
            "gain" | "let" if self.peek2() == Tok::Ident => {
                self.bump();
                let name = self.ident("a name")?;
                self.expect(Tok::Eq, "`=`")?;
                self.skip_newlines();
                let value = self.statement_expr(start)?;
                let span = Span::new(start, self.prev_end());
                if kw == "gain" {
                    RecordedStmt::Gain { name, value, span }
                } else {
                    RecordedStmt::Let { name, value, span }
                }
            }
            _ if t.tok == Tok::Ident && self.peek2() == Tok::Eq => {
                let target = self.ident("an input name")?;
                self.bump();
                self.skip_newlines();
                let expr = self.statement_expr(start)?;
                RecordedStmt::Law {
                    target,
                    expr,
                    span: Span::new(start, self.prev_end()),
                }
            }
            _ => {
                let found = self.found(&t);
                self.error(
                    Diagnostic::error(
                        "plantc::unknown_recorded_statement",
                        format!("expected a recorded-controller statement, found {found}"),
                        t.span,
                        "not a recorded-controller statement",
                    )
                    .with_help(
                        "a recorded controller has `signal name [unit]` lines (data columns), `gain name = value`, `let name = expr` and one law per driven input, `Vm = ...`",
                    ),
                );
                return Err(());
            }
        };
        Ok(stmt)
    }

    // ---- literals ----

    fn list<T>(&mut self, mut item: impl FnMut(&mut Self) -> PResult<T>) -> PResult<Vec<T>> {
        self.expect(Tok::LBracket, "`[`")?;
        self.nl_depth += 1;
        let mut v = Vec::new();
        loop {
            if *self.peek() == Tok::RBracket {
                break;
            }
            v.push(item(self)?);
            if *self.peek() == Tok::Comma {
                self.bump();
            } else if *self.peek() != Tok::RBracket {
                return self.unexpected("`,` or `]`");
            }
        }
        self.nl_depth -= 1;
        self.bump();
        Ok(v)
    }

    fn signed_num(&mut self) -> PResult<NumLit> {
        let t = self.peek_token();
        let (neg, start) = match t.tok {
            Tok::Minus => {
                self.bump();
                (true, t.span.start)
            }
            Tok::Plus => {
                self.bump();
                (false, t.span.start)
            }
            _ => (false, t.span.start),
        };
        let n = self.expect(Tok::Number, "a number")?;
        let digits = self.text(n.span);
        Ok(NumLit {
            text: if neg {
                format!("-{digits}")
            } else {
                digits.to_string()
            },
            span: Span::new(start, n.span.end),
        })
    }

    fn complex(&mut self) -> PResult<ComplexLit> {
        let t = self.peek_token();
        let start = t.span.start;
        let mut sign = "";
        if matches!(t.tok, Tok::Minus | Tok::Plus) {
            if t.tok == Tok::Minus {
                sign = "-";
            }
            self.bump();
        }
        let n = self.peek_token();
        match n.tok {
            Tok::Imag => {
                self.bump();
                let d = self.text(n.span);
                Ok(ComplexLit {
                    re: None,
                    im: Some(NumLit {
                        text: format!("{sign}{}", &d[..d.len() - 1]),
                        span: Span::new(start, n.span.end),
                    }),
                    span: Span::new(start, n.span.end),
                })
            }
            Tok::Number => {
                self.bump();
                let re = NumLit {
                    text: format!("{sign}{}", self.text(n.span)),
                    span: Span::new(start, n.span.end),
                };
                let op = self.peek_token();
                if matches!(op.tok, Tok::Plus | Tok::Minus) && self.peek2() == Tok::Imag {
                    self.bump();
                    let im = self.bump();
                    let d = self.text(im.span);
                    let s2 = if op.tok == Tok::Minus { "-" } else { "" };
                    return Ok(ComplexLit {
                        re: Some(re),
                        im: Some(NumLit {
                            text: format!("{s2}{}", &d[..d.len() - 1]),
                            span: Span::new(op.span.start, im.span.end),
                        }),
                        span: Span::new(start, im.span.end),
                    });
                }
                Ok(ComplexLit {
                    re: Some(re),
                    im: None,
                    span: Span::new(start, n.span.end),
                })
            }
            _ => self.unexpected("a pole such as `-40` or `-2+3.464i`"),
        }
    }

    fn bounds(&mut self) -> PResult<Bounds> {
        let open = self.expect(Tok::LBracket, "`[`")?;
        self.nl_depth += 1;
        let lo = self.signed_num()?;
        self.expect(Tok::Comma, "`,`")?;
        let hi = self.signed_num()?;
        let close = self.expect(Tok::RBracket, "`]`")?;
        self.nl_depth -= 1;
        Ok(Bounds {
            lo,
            hi,
            span: open.span.to(close.span),
        })
    }

    fn unit(&mut self) -> PResult<UnitExpr> {
        let open = self.bump();
        let start = open.span.end;
        let mut end = start;
        loop {
            let t = self.toks[self.pos].clone();
            match t.tok {
                Tok::RBracket => {
                    self.pos += 1;
                    let text = self.src[start..end].trim().to_string();
                    let lead = self.src[start..end].len() - self.src[start..end].trim_start().len();
                    return Ok(UnitExpr {
                        span: Span::new(start + lead, start + lead + text.len()),
                        text,
                        outer: open.span.to(t.span),
                    });
                }
                Tok::Newline
                | Tok::Eof
                | Tok::LBracket
                | Tok::LBrace
                | Tok::RBrace
                | Tok::Str(_) => {
                    self.error(
                        Diagnostic::error(
                            "plantc::syntax",
                            "unclosed `[` in a unit",
                            open.span,
                            "this `[` is not closed",
                        )
                        .with_label(Span::new(t.span.start, t.span.start), "expected `]` here")
                        .with_help("units are written in brackets on one line, e.g. `[kg*m^2]`"),
                    );
                    return Err(());
                }
                _ => {
                    end = t.span.end;
                    self.pos += 1;
                }
            }
        }
    }

    // ---- expressions ----

    /// An expression that may continue on following lines starting with `+`
    /// or `-` when those are indented more than the statement's first line.
    fn statement_expr(&mut self, stmt_start: usize) -> PResult<Expr> {
        self.cont_indent = Some(self.column(stmt_start));
        let e = self.expr();
        self.cont_indent = None;
        e
    }

    /// After a binary operator a line break continues the expression, unless
    /// the next line starts a new declaration (then the operator is a typo).
    fn skip_after_operator(&mut self, op: Span) -> PResult<()> {
        if self.toks[self.pos].tok != Tok::Newline {
            return Ok(());
        }
        self.skip_newlines();
        let t = self.toks[self.pos].clone();
        if t.tok == Tok::Ident
            && KEYWORDS.contains(&self.text(t.span))
            && self.column(t.span.start) == 0
        {
            self.error(
                Diagnostic::error(
                    "plantc::syntax",
                    "expression ends with an operator",
                    op,
                    "nothing follows this operator",
                )
                .with_label(t.span, "the next line starts a new declaration")
                .with_help("complete the expression or remove the trailing operator; a line ending with an operator continues on the next line"),
            );
            return Err(());
        }
        Ok(())
    }

    fn enter(&mut self) -> PResult<()> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            let t = self.peek_token();
            self.error(Diagnostic::error(
                "plantc::too_deep",
                "expression nested too deeply",
                t.span,
                "nesting limit reached here",
            ));
            return Err(());
        }
        Ok(())
    }

    fn expr(&mut self) -> PResult<Expr> {
        self.enter()?;
        let r = self.additive();
        self.depth -= 1;
        let e = r?;
        if self.depth == 0 && height(&e) > MAX_HEIGHT {
            self.error(
                Diagnostic::error(
                    "plantc::too_deep",
                    "expression nested too deeply",
                    e.span,
                    format!("more than {MAX_HEIGHT} levels of nesting"),
                )
                .with_help("split it with `let` definitions"),
            );
            return Err(());
        }
        Ok(e)
    }

    fn continuation_line(&mut self) -> bool {
        let Some(indent) = self.cont_indent else {
            return false;
        };
        if self.nl_depth > 0 || self.toks[self.pos].tok != Tok::Newline {
            return false;
        }
        let mut j = self.pos;
        while self.toks[j].tok == Tok::Newline {
            j += 1;
        }
        let t = &self.toks[j];
        if matches!(t.tok, Tok::Plus | Tok::Minus) && self.column(t.span.start) > indent {
            self.pos = j;
            true
        } else {
            false
        }
    }

    fn additive(&mut self) -> PResult<Expr> {
        let first = self.term()?;
        let mut rest = Vec::new();
        loop {
            let t = self.peek().clone();
            let op = match t {
                Tok::Plus => BinOp::Add,
                Tok::Minus => BinOp::Sub,
                Tok::Newline if self.continuation_line() => continue,
                _ => break,
            };
            let op_tok = self.bump();
            self.skip_after_operator(op_tok.span)?;
            rest.push((op, self.term()?));
        }
        Ok(chain(first, rest))
    }

    fn term(&mut self) -> PResult<Expr> {
        let first = self.unary()?;
        let mut rest = Vec::new();
        loop {
            let op = match self.peek() {
                Tok::Star => BinOp::Mul,
                Tok::Slash => BinOp::Div,
                _ => break,
            };
            let op_tok = self.bump();
            self.skip_after_operator(op_tok.span)?;
            rest.push((op, self.unary()?));
        }
        Ok(chain(first, rest))
    }

    fn unary(&mut self) -> PResult<Expr> {
        self.enter()?;
        let r = self.unary_inner();
        self.depth -= 1;
        r
    }

    fn unary_inner(&mut self) -> PResult<Expr> {
        let t = self.peek_token();
        match t.tok {
            Tok::Minus => {
                self.bump();
                let e = self.unary()?;
                let span = t.span.to(e.span);
                Ok(Expr::new(ExprKind::Neg(Box::new(e)), span))
            }
            Tok::Plus => {
                self.bump();
                self.unary()
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> PResult<Expr> {
        let base = self.primary()?;
        let t = self.peek_token();
        if t.tok == Tok::Prime {
            self.error(
                Diagnostic::error(
                    "plantc::bad_derivative",
                    "a time derivative `'` can only follow a coordinate name",
                    t.span,
                    "cannot differentiate this",
                )
                .with_label(base.span, "this is not a plain name")
                .with_help("write derivatives of coordinates only, e.g. `theta'` or `theta''`"),
            );
            return Err(());
        }
        if t.tok == Tok::Caret {
            let op_tok = self.bump();
            self.skip_after_operator(op_tok.span)?;
            let exp = self.unary()?;
            let span = base.span.to(exp.span);
            return Ok(Expr::new(
                ExprKind::Binary(BinOp::Pow, Box::new(base), Box::new(exp)),
                span,
            ));
        }
        Ok(base)
    }

    fn primary(&mut self) -> PResult<Expr> {
        let t = self.peek_token();
        match t.tok {
            Tok::Number => {
                self.bump();
                let n = NumLit {
                    text: self.text(t.span).to_string(),
                    span: t.span,
                };
                if self.toks[self.pos].tok == Tok::LBracket {
                    let u = self.unit()?;
                    let span = t.span.to(u.outer);
                    return Ok(Expr::new(ExprKind::Quantity(n, u), span));
                }
                Ok(Expr::new(ExprKind::Number(n), t.span))
            }
            Tok::Imag => {
                self.error(
                    Diagnostic::error(
                        "plantc::complex_literal",
                        "complex numbers are only allowed in `place poles [...]`",
                        t.span,
                        "imaginary literal",
                    )
                    .with_help("model expressions are real-valued"),
                );
                Err(())
            }
            Tok::Ident => {
                self.bump();
                let name = self.text(t.span).to_string();
                if *self.peek() == Tok::LParen {
                    let open = self.bump();
                    self.nl_depth += 1;
                    let mut args = Vec::new();
                    if *self.peek() != Tok::RParen {
                        loop {
                            args.push(self.expr()?);
                            if *self.peek() == Tok::Comma {
                                self.bump();
                            } else {
                                break;
                            }
                        }
                    }
                    if *self.peek() != Tok::RParen {
                        let _ = self.unexpected::<()>("`,` or `)`");
                        if let Some(d) = self.diags.last_mut() {
                            d.secondary.push(super::diagnostic::Label {
                                span: open.span,
                                text: "call opened here".into(),
                            });
                        }
                        return Err(());
                    }
                    let close = self.bump();
                    self.nl_depth -= 1;
                    return Ok(Expr::new(
                        ExprKind::Call(Ident { name, span: t.span }, args),
                        t.span.to(close.span),
                    ));
                }
                let mut order = 0usize;
                let mut end = t.span.end;
                while self.toks[self.pos].tok == Tok::Prime {
                    end = self.toks[self.pos].span.end;
                    order += 1;
                    self.pos += 1;
                }
                let span = Span::new(t.span.start, end);
                if order > 2 {
                    self.error(
                        Diagnostic::error(
                            "plantc::bad_derivative",
                            format!("derivative of order {order} is not supported"),
                            span,
                            "too many `'`",
                        )
                        .with_help(
                            "only first (`q'`) and second (`q''`) time derivatives are allowed",
                        ),
                    );
                    return Err(());
                }
                if order > 0 {
                    return Ok(Expr::new(ExprKind::Deriv(name, order as u8), span));
                }
                if name == "pi" {
                    return Ok(Expr::new(ExprKind::Pi, span));
                }
                Ok(Expr::new(ExprKind::Name(name), span))
            }
            Tok::LParen => {
                self.bump();
                self.nl_depth += 1;
                let inner = self.expr()?;
                if *self.peek() != Tok::RParen {
                    let _ = self.unexpected::<()>("`)`");
                    if let Some(d) = self.diags.last_mut() {
                        d.secondary.push(super::diagnostic::Label {
                            span: t.span,
                            text: "unclosed `(`".into(),
                        });
                    }
                    return Err(());
                }
                let close = self.bump();
                self.nl_depth -= 1;
                Ok(Expr::new(inner.kind, t.span.to(close.span)))
            }
            _ => self.unexpected("an expression"),
        }
    }
}

/// `first op1 e1 op2 e2 ...` of one precedence level (`+`/`-` or `*`/`/`):
/// left-deep for short chains, balanced for long ones (see [`CHAIN_BALANCE`]).
fn chain(first: Expr, rest: Vec<(BinOp, Expr)>) -> Expr {
    if rest.len() < CHAIN_BALANCE {
        return rest.into_iter().fold(first, |lhs, (op, rhs)| {
            let span = lhs.span.to(rhs.span);
            Expr::new(ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)), span)
        });
    }
    let mut items: Vec<(BinOp, Option<Expr>)> = Vec::with_capacity(rest.len() + 1);
    let positive = match rest[0].0 {
        BinOp::Add | BinOp::Sub => BinOp::Add,
        _ => BinOp::Mul,
    };
    items.push((positive, Some(first)));
    items.extend(rest.into_iter().map(|(op, e)| (op, Some(e))));
    balanced(&mut items, false)
}

/// The inverse operator: `-` for `+`, `/` for `*`.
fn inverse(op: BinOp) -> BinOp {
    match op {
        BinOp::Add => BinOp::Sub,
        BinOp::Sub => BinOp::Add,
        BinOp::Mul => BinOp::Div,
        BinOp::Div => BinOp::Mul,
        BinOp::Pow => BinOp::Pow,
    }
}

/// The value of `items` (the first operand taken positively, every later
/// operator inverted when `flip`) as a balanced tree:
/// `a - b + c - d = (a - b) + (c - d)`, `a - b - c + d = (a - b) - (c - d)`.
fn balanced(items: &mut [(BinOp, Option<Expr>)], flip: bool) -> Expr {
    if items.len() == 1 {
        return items[0].1.take().expect("each operand is used once");
    }
    let mid = items.len() / 2;
    let (left, right) = items.split_at_mut(mid);
    let lhs = balanced(left, flip);
    let op = if flip {
        inverse(right[0].0)
    } else {
        right[0].0
    };
    let rhs = balanced(right, flip ^ matches!(op, BinOp::Sub | BinOp::Div));
    let span = lhs.span.to(rhs.span);
    Expr::new(ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)), span)
}

/// Height of an expression tree, without recursion.
pub fn height(e: &Expr) -> usize {
    let mut max = 0;
    let mut stack = vec![(e, 1usize)];
    while let Some((e, h)) = stack.pop() {
        max = max.max(h);
        match &e.kind {
            ExprKind::Neg(a) => stack.push((a, h + 1)),
            ExprKind::Binary(_, a, b) => {
                stack.push((a, h + 1));
                stack.push((b, h + 1));
            }
            ExprKind::Call(_, args) => stack.extend(args.iter().map(|a| (a, h + 1))),
            _ => {}
        }
    }
    max
}
