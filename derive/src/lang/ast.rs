//! Syntax tree of a `.plant` file. Every node carries its [`Span`].

use super::span::Span;

/// A name as written, with its location.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ident {
    /// The name.
    pub name: String,
    /// Where it is written.
    pub span: Span,
}

/// A string literal (doc text), unescaped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StrLit {
    /// Value without quotes.
    pub value: String,
    /// Span including the quotes.
    pub span: Span,
}

/// A number literal, keeping its source text (with a leading `-` when the
/// literal was written negative in a literal-only position such as a
/// parameter value, bounds or lists), so it can be converted exactly.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NumLit {
    /// Text such as `9.98e-4` or `-10`.
    pub text: String,
    /// Span of the literal (including the sign, if any).
    pub span: Span,
}

impl NumLit {
    /// The value as a float.
    pub fn value(&self) -> f64 {
        self.text.parse().unwrap_or(f64::NAN)
    }
}

/// A unit in brackets, e.g. `[kg*m^2]`; resolved by [`super::units::parse_unit`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnitExpr {
    /// Text between the brackets.
    pub text: String,
    /// Span of the text between the brackets.
    pub span: Span,
    /// Span including the brackets.
    pub outer: Span,
}

/// A `[lo, hi]` pair of literals.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Bounds {
    /// Lower bound.
    pub lo: NumLit,
    /// Upper bound.
    pub hi: NumLit,
    /// Span of `[lo, hi]` including the brackets.
    pub span: Span,
}

/// `model name "title"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelDecl {
    /// Model name.
    pub name: Ident,
    /// Optional title.
    pub title: Option<StrLit>,
    /// Whole statement.
    pub span: Span,
}

/// Kind of a generalised coordinate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoordKind {
    /// Unit rad (dimensionless).
    Angle,
    /// Unit m.
    Length,
}

/// `coordinate theta : angle "doc"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Coordinate {
    /// Name.
    pub name: Ident,
    /// Angle or length.
    pub kind: CoordKind,
    /// Where the kind is written.
    pub kind_span: Span,
    /// Optional description.
    pub doc: Option<StrLit>,
    /// Whole statement.
    pub span: Span,
}

/// `input Vm [V] limits [-10, 10] "doc"`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Input {
    /// Name.
    pub name: Ident,
    /// Unit; none means dimensionless.
    pub unit: Option<UnitExpr>,
    /// Optional saturation limits, in the input's unit.
    pub limits: Option<Bounds>,
    /// Optional description.
    pub doc: Option<StrLit>,
    /// Whole statement.
    pub span: Span,
}

/// `output alpha` or `output tip = L1*theta`.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    /// Name (a coordinate or let for the short form).
    pub name: Ident,
    /// Defining expression for the named form.
    pub expr: Option<Expr>,
    /// Optional description.
    pub doc: Option<StrLit>,
    /// Whole statement.
    pub span: Span,
}

/// `parameter J1 = 9.98e-4 [kg*m^2] "doc" estimate [1e-4, 5e-3]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Parameter {
    /// Name.
    pub name: Ident,
    /// Value literal in the declared unit (its span is what an edit replaces).
    pub value: NumLit,
    /// Declared unit; none means dimensionless.
    pub unit: Option<UnitExpr>,
    /// Optional description.
    pub doc: Option<StrLit>,
    /// Optional estimation bounds, in the declared unit.
    pub estimate: Option<Bounds>,
    /// Whole statement (up to its last token, comments excluded).
    pub span: Span,
}

/// `let name = expr`.
#[derive(Debug, Clone, PartialEq)]
pub struct Let {
    /// Name.
    pub name: Ident,
    /// Definition.
    pub expr: Expr,
    /// Whole statement.
    pub span: Span,
}

/// `kinetic T = expr` or `potential V = expr`.
#[derive(Debug, Clone, PartialEq)]
pub struct Energy {
    /// Name (`T`, `V`).
    pub name: Ident,
    /// Definition.
    pub expr: Expr,
    /// Whole statement.
    pub span: Span,
}

/// `force q = expr`: the generalised force on coordinate `q`.
#[derive(Debug, Clone, PartialEq)]
pub struct Force {
    /// The coordinate.
    pub coordinate: Ident,
    /// The expression as written (effects are calls).
    pub written: Expr,
    /// After checking: effects expanded into plain expressions (spans point at
    /// the calls). Equal to `written` straight out of the parser.
    pub expr: Expr,
    /// Byte offset just after the expression (where a term can be appended).
    pub expr_end: usize,
    /// Whole statement.
    pub span: Span,
}

/// `sensor q = sensor_offset(d)` or `actuator u = input_delay(Td)`: one
/// measurement or input effect on a coordinate or an input. Several lines may
/// target the same name; their effects compose.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalEffect {
    /// [`EffectKind::Sensor`](super::effects::EffectKind::Sensor) for a
    /// `sensor` line, `Actuator` for an `actuator` line.
    pub kind: super::effects::EffectKind,
    /// The coordinate (sensor lines) or input (actuator lines).
    pub target: Ident,
    /// The effect call as written.
    pub call: Expr,
    /// Whole statement.
    pub span: Span,
}

impl SignalEffect {
    /// The effect's name, when the line holds a call.
    pub fn effect_name(&self) -> Option<&str> {
        match &self.call.kind {
            ExprKind::Call(f, _) => Some(&f.name),
            _ => None,
        }
    }

    /// The effect's arguments (empty when the line holds no call).
    pub fn args(&self) -> &[Expr] {
        match &self.call.kind {
            ExprKind::Call(_, a) => a,
            _ => &[],
        }
    }
}

impl std::fmt::Display for SignalEffect {
    /// The line in model-language text, e.g. `sensor alpha = sensor_offset(d)`
    /// (arguments fully parenthesised).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {} = {}",
            self.kind.keyword(),
            self.target.name,
            self.call
        )
    }
}

/// `name = expr` inside a `set`.
#[derive(Debug, Clone, PartialEq)]
pub struct SetEntry {
    /// The parameter.
    pub name: Ident,
    /// Its value in this set; may use quantity literals like `0.1685 [m]`
    /// and the parameters' declared values.
    pub value: Expr,
    /// Whole entry.
    pub span: Span,
}

/// `set name "title" { entries }`: alternative parameter values.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSet {
    /// Name.
    pub name: Ident,
    /// Optional description.
    pub title: Option<StrLit>,
    /// The overrides.
    pub entries: Vec<SetEntry>,
    /// Whole block.
    pub span: Span,
}

/// A pole in a `place poles [...]` list: `re`, `re+imi`, `imi`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ComplexLit {
    /// Real part, if written.
    pub re: Option<NumLit>,
    /// Imaginary part (text includes its sign, not the `i`), if written.
    pub im: Option<NumLit>,
    /// Whole literal.
    pub span: Span,
}

impl ComplexLit {
    /// (re, im) as floats.
    pub fn value(&self) -> (f64, f64) {
        (
            self.re.as_ref().map_or(0.0, NumLit::value),
            self.im.as_ref().map_or(0.0, NumLit::value),
        )
    }
}

/// One statement of a `controller` block.
#[derive(Debug, Clone, PartialEq)]
pub enum ControllerStmt {
    /// `place poles [..]`.
    Place {
        /// Desired closed-loop poles.
        poles: Vec<ComplexLit>,
        /// Statement span.
        span: Span,
    },
    /// `lqr Q [..] R [..]` (diagonals).
    Lqr {
        /// State weights.
        q: Vec<NumLit>,
        /// Input weights.
        r: Vec<NumLit>,
        /// Statement span.
        span: Span,
    },
    /// `gains K [..]`: a given state-feedback gain `u = -K x`.
    Gains {
        /// Gain name.
        name: Ident,
        /// Entries.
        values: Vec<NumLit>,
        /// Statement span.
        span: Span,
    },
    /// `linearize output y`: feedback linearization of an output.
    Linearize {
        /// The output.
        output: Ident,
        /// Statement span.
        span: Span,
    },
    /// `gain wn = 4`: a named constant usable in the law.
    Gain {
        /// Name.
        name: Ident,
        /// Value.
        value: Expr,
        /// Statement span.
        span: Span,
    },
    /// `v = expr`: the outer law (`y`, `y'` are the output and its derivative).
    Law {
        /// Left-hand side (must be `v`).
        target: Ident,
        /// Right-hand side.
        expr: Expr,
        /// Statement span.
        span: Span,
    },
}

impl ControllerStmt {
    /// Statement span.
    pub fn span(&self) -> Span {
        match self {
            ControllerStmt::Place { span, .. }
            | ControllerStmt::Lqr { span, .. }
            | ControllerStmt::Gains { span, .. }
            | ControllerStmt::Linearize { span, .. }
            | ControllerStmt::Gain { span, .. }
            | ControllerStmt::Law { span, .. } => *span,
        }
    }
}

/// `controller name "title" { statements }`.
#[derive(Debug, Clone, PartialEq)]
pub struct Controller {
    /// Name.
    pub name: Ident,
    /// Optional description.
    pub title: Option<StrLit>,
    /// Statements in order.
    pub body: Vec<ControllerStmt>,
    /// Whole block.
    pub span: Span,
}

/// One statement of a `recorded controller` block.
#[derive(Debug, Clone, PartialEq)]
pub enum RecordedStmt {
    /// `signal name [unit] "title"`: a data column the law reads (a
    /// reference, a feedforward...).
    Signal {
        /// Column name.
        name: Ident,
        /// Its unit (SI when absent: dimensionless).
        unit: Option<UnitExpr>,
        /// Optional description.
        title: Option<StrLit>,
        /// Statement span.
        span: Span,
    },
    /// `gain name = value`: a named constant (may carry a unit).
    Gain {
        /// Name.
        name: Ident,
        /// Value.
        value: Expr,
        /// Statement span.
        span: Span,
    },
    /// `let name = expr`: a named intermediate of the law.
    Let {
        /// Name.
        name: Ident,
        /// Definition.
        value: Expr,
        /// Statement span.
        span: Span,
    },
    /// `u = expr`: the value the controller writes to input `u`.
    Law {
        /// The input driven.
        target: Ident,
        /// Right-hand side.
        expr: Expr,
        /// Statement span.
        span: Span,
    },
}

impl RecordedStmt {
    /// Statement span.
    pub fn span(&self) -> Span {
        match self {
            RecordedStmt::Signal { span, .. }
            | RecordedStmt::Gain { span, .. }
            | RecordedStmt::Let { span, .. }
            | RecordedStmt::Law { span, .. } => *span,
        }
    }
}

/// `recorded controller name "title" { statements }`: the discrete-time law
/// that drove some inputs while the data were recorded, evaluated at every
/// sample instant from the measured coordinates and data columns.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedController {
    /// Name.
    pub name: Ident,
    /// Optional description.
    pub title: Option<StrLit>,
    /// Statements in order.
    pub body: Vec<RecordedStmt>,
    /// Whole block.
    pub span: Span,
}

/// A whole model file. Declarations are grouped by kind, each list in source order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ModelFile {
    /// `model` line.
    pub model: Option<ModelDecl>,
    /// Coordinates.
    pub coordinates: Vec<Coordinate>,
    /// Inputs.
    pub inputs: Vec<Input>,
    /// Outputs.
    pub outputs: Vec<Output>,
    /// Parameters.
    pub parameters: Vec<Parameter>,
    /// Intermediate definitions.
    pub lets: Vec<Let>,
    /// Kinetic energy.
    pub kinetic: Vec<Energy>,
    /// Potential energy.
    pub potential: Vec<Energy>,
    /// Generalised forces.
    pub forces: Vec<Force>,
    /// `sensor` lines (measurement effects on coordinates).
    pub sensors: Vec<SignalEffect>,
    /// `actuator` lines (effects on inputs).
    pub actuators: Vec<SignalEffect>,
    /// Parameter sets.
    pub sets: Vec<ParamSet>,
    /// Controllers.
    pub controllers: Vec<Controller>,
    /// Controllers that ran while data were recorded.
    pub recorded: Vec<RecordedController>,
}

/// Binary operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `^` (right-associative)
    Pow,
}

impl BinOp {
    /// The operator symbol.
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Pow => "^",
        }
    }
}

/// An expression with its span.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    /// What it is.
    pub kind: ExprKind,
    /// Where it is.
    pub span: Span,
}

/// Expression forms.
#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    /// A dimensionless number.
    Number(NumLit),
    /// A number with a unit, e.g. `0.1685 [m]` (allowed in set values).
    Quantity(NumLit, UnitExpr),
    /// A reference to a declared name.
    Name(String),
    /// The constant pi.
    Pi,
    /// Time derivative `q'` (order 1) or `q''` (order 2).
    Deriv(String, u8),
    /// Negation.
    Neg(Box<Expr>),
    /// Binary operation.
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// Call of a built-in function or an effect.
    Call(Ident, Vec<Expr>),
}

impl Expr {
    /// Builds an expression.
    pub fn new(kind: ExprKind, span: Span) -> Expr {
        Expr { kind, span }
    }

    /// Calls `f` on this expression and every sub-expression (pre-order).
    pub fn walk<'a>(&'a self, f: &mut dyn FnMut(&'a Expr)) {
        f(self);
        match &self.kind {
            ExprKind::Neg(a) => a.walk(f),
            ExprKind::Binary(_, a, b) => {
                a.walk(f);
                b.walk(f);
            }
            ExprKind::Call(_, args) => args.iter().for_each(|a| a.walk(f)),
            _ => {}
        }
    }
}

impl std::fmt::Display for Expr {
    /// Fully parenthesised model-language text.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.kind {
            ExprKind::Number(n) => f.write_str(&n.text),
            ExprKind::Quantity(n, u) => write!(f, "{} [{}]", n.text, u.text),
            ExprKind::Name(n) => f.write_str(n),
            ExprKind::Pi => f.write_str("pi"),
            ExprKind::Deriv(n, k) => write!(f, "{n}{}", "'".repeat(*k as usize)),
            ExprKind::Neg(a) => write!(f, "(-{a})"),
            ExprKind::Binary(op, a, b) => write!(f, "({a} {} {b})", op.symbol()),
            ExprKind::Call(name, args) => {
                write!(f, "{}(", name.name)?;
                for (i, a) in args.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{a}")?;
                }
                f.write_str(")")
            }
        }
    }
}
