//! The symbolic model: what a checked `.plant` file means, independent of its
//! syntax. Produced by [`lower`] from the checked AST; consumed by mechanics,
//! analysis, code generation and identification.

mod chain;
mod lower;
mod modes;
mod values;

pub use chain::n_link_chain_source;
pub use lower::{
    load_model, load_model_text, lower, read_regular_file, read_source, LoadError, LoadedModel,
};
pub use modes::{Guard, ModeSpec, SurfaceSpec, SwitchSpec};
pub use values::{ParameterValues, ValuesError};

use crate::sym::{CoordinateSymbols, Expr, Symbol};

/// What a generalised coordinate measures.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CoordinateKind {
    /// An angle in rad; its generalised force is a torque.
    Angle,
    /// A length in m; its generalised force is a force.
    Length,
}

/// A generalised coordinate `q` with its velocity `q'` and acceleration `q''`.
#[derive(Clone, Debug)]
pub struct Coordinate {
    /// Name as written in the model file.
    pub name: String,
    /// Angle or length.
    pub kind: CoordinateKind,
    /// The symbols `q`, `q'`, `q''`.
    pub symbols: CoordinateSymbols,
    /// Free-text description.
    pub description: Option<String>,
}

/// An input (actuator command).
#[derive(Clone, Debug)]
pub struct Input {
    /// Name, e.g. `Vm`.
    pub name: String,
    /// Its symbol.
    pub symbol: Symbol,
    /// Unit as written, e.g. `V`.
    pub unit: String,
    /// Saturation limits `(lo, hi)` in SI units, if declared.
    pub limits: Option<(f64, f64)>,
    /// Free-text description.
    pub description: Option<String>,
}

/// A measured or controlled output `y = h(q, q')`.
#[derive(Clone, Debug)]
pub struct Output {
    /// Name (a coordinate's name for `output alpha`).
    pub name: String,
    /// The expression `h`, over coordinates, velocities and parameters.
    pub expr: Expr,
}

/// A physical parameter with its nominal value.
#[derive(Clone, Debug)]
pub struct Parameter {
    /// Name.
    pub name: String,
    /// Its symbol.
    pub symbol: Symbol,
    /// Nominal value in SI units.
    pub value: f64,
    /// Unit as written.
    pub unit: String,
    /// Free-text description.
    pub description: Option<String>,
    /// Bounds `(lo, hi)` in SI units if the parameter is marked `estimate`.
    pub estimate: Option<(f64, f64)>,
}

/// A named set of parameter overrides.
#[derive(Clone, Debug)]
pub struct ParameterSet {
    /// Name used with `--set`.
    pub name: String,
    /// Free-text description.
    pub description: Option<String>,
    /// Overridden values in SI units, in file order.
    pub values: Vec<(String, f64)>,
}

/// A definition that depends on parameters only (`let J0h = J1 + m1*l1^2 + ...`).
/// It stays a symbol in the equations (so they read like a textbook) and is
/// evaluated from the parameter values.
#[derive(Clone, Debug)]
pub struct Derived {
    /// Name.
    pub name: String,
    /// Its symbol.
    pub symbol: Symbol,
    /// Definition over parameters and earlier derived quantities.
    pub expr: Expr,
}

/// A controller declared in the model file (design data only; the analysis and
/// code-generation layers give it meaning).
#[derive(Clone, Debug, PartialEq)]
pub enum ControllerSpec {
    /// `u = -K x` with given gains (one row per input).
    Gains {
        /// Name.
        name: String,
        /// Gains, row-major, one row per input.
        k: Vec<Vec<f64>>,
    },
    /// `u = -K x` with K placed at the given poles.
    Place {
        /// Name.
        name: String,
        /// Desired closed-loop poles `(re, im)`.
        poles: Vec<(f64, f64)>,
    },
    /// LQR with diagonal weights.
    Lqr {
        /// Name.
        name: String,
        /// Diagonal of Q.
        q: Vec<f64>,
        /// Diagonal of R.
        r: Vec<f64>,
    },
    /// Input-output feedback linearization of an output with an outer law `v`.
    FeedbackLinearization {
        /// Name.
        name: String,
        /// The output linearized.
        output: String,
        /// Named gains with their values (in file order).
        gains: Vec<(String, f64)>,
        /// The outer law `v` over `y`, `y'`, ..., coordinates, velocities and gains.
        v: Expr,
    },
    /// A law for every input written directly, e.g. the energy swing-up
    /// `Vm = kE*(0 - energy(alpha))*sign(alpha'*cos(alpha)) - k_theta*theta`.
    /// `energy(q)` is lowered to the kinetic energy with the other
    /// coordinates' velocities at 0 plus `V - V|q=0`; `sat(x)` to
    /// `(|x + 1| - |x - 1|)/2`, i.e. `x` clamped to [-1, 1].
    Direct {
        /// Name.
        name: String,
        /// Named gains with their values (in file order).
        gains: Vec<(String, f64)>,
        /// One law per input, in input order, over the state, parameters and gains.
        laws: Vec<Expr>,
    },
    /// Sliding mode on a surface `s`: `u = (v - L_f s) / L_g s`, i.e. the
    /// equivalent control plus the reaching law `s' = v` (e.g.
    /// `v = -k*sat(s/phi)`, a switching term with a boundary layer).
    SlidingMode {
        /// Name.
        name: String,
        /// The surface's name as used in `v`.
        surface_name: String,
        /// The surface.
        surface: SurfaceSpec,
        /// Named gains with their values (in file order).
        gains: Vec<(String, f64)>,
        /// The reaching law `v` over the surface symbol, the state, parameters and gains.
        v: Expr,
    },
    /// A controller made of modes (other controllers of the file) with
    /// switch conditions; the first mode is the initial one.
    Hybrid {
        /// Name.
        name: String,
        /// Modes in file order.
        modes: Vec<ModeSpec>,
        /// Switches in file order (the first one whose condition holds wins).
        switches: Vec<SwitchSpec>,
        /// Coordinates (indices) the modes and conditions see wrapped into (-pi, pi].
        wrap: Vec<usize>,
    },
}

impl ControllerSpec {
    /// The controller's name.
    pub fn name(&self) -> &str {
        match self {
            ControllerSpec::Gains { name, .. }
            | ControllerSpec::Place { name, .. }
            | ControllerSpec::Lqr { name, .. }
            | ControllerSpec::FeedbackLinearization { name, .. }
            | ControllerSpec::Direct { name, .. }
            | ControllerSpec::SlidingMode { name, .. }
            | ControllerSpec::Hybrid { name, .. } => name,
        }
    }
}

/// A data column read by a [`RecordedController`].
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedSignal {
    /// Column name.
    pub name: String,
    /// Its symbol in the laws.
    pub symbol: Symbol,
    /// Unit as written (data are read in SI).
    pub unit: String,
    /// Description.
    pub description: Option<String>,
}

/// A filtered derivative `derivative(x, wc)` of a [`RecordedController`]:
/// `wc s/(s + wc)` discretised by backward Euler at the record's sample
/// period `T`, `y_k = a (x_k - x_{k-1}) + b y_{k-1}` with `b = 1/(1 + wc T)`
/// and `a = wc b`, started at rest (`x_{-1} = y_{-1} = 0`, as a discrete
/// filter whose state is zeroed when the controller starts).
#[derive(Clone, Debug, PartialEq)]
pub struct DerivativeFilter {
    /// The symbol standing for the filter's output in the laws.
    pub symbol: Symbol,
    /// Its input `x`, over measured coordinates, signals and parameters.
    pub input: Expr,
    /// Cutoff `wc` in rad/s (SI), evaluated at the nominal parameters.
    pub cutoff: f64,
}

/// The controller that drove some inputs while data were recorded
/// (`recorded controller` block): a discrete-time law evaluated at every
/// sample instant from the measured coordinates and data columns. The
/// simulation of a recording with this controller in the loop reproduces
/// closed-loop experiments (identification's `--closed-loop`).
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedController {
    /// Name.
    pub name: String,
    /// Description.
    pub description: Option<String>,
    /// Data columns the laws read.
    pub signals: Vec<RecordedSignal>,
    /// Filtered derivatives, in order of appearance.
    pub filters: Vec<DerivativeFilter>,
    /// `(input index, law)`: each law is over the coordinates' position
    /// symbols (the measured values), signal symbols, filter symbols and
    /// parameters (gains and local `let`s inlined), in SI.
    pub laws: Vec<(usize, Expr)>,
}

/// What a `sensor` line does to the measurement of a coordinate.
#[derive(Clone, Debug, PartialEq)]
pub enum SensorEffectKind {
    /// `sensor q = sensor_offset(d)`: the encoder reads `q + d`; the
    /// expression `d` is over parameters (SI, the coordinate's unit).
    Offset(Expr),
}

/// A measurement effect on one coordinate (`sensor q = ...`).
#[derive(Clone, Debug, PartialEq)]
pub struct SensorEffect {
    /// Index of the coordinate in [`Model::coordinates`].
    pub coordinate: usize,
    /// The effect with its parameter expression.
    pub effect: SensorEffectKind,
}

/// What an `actuator` line does to an input on its way to the plant.
#[derive(Clone, Debug, PartialEq)]
pub enum ActuatorEffectKind {
    /// `actuator u = input_offset(V0)`: the plant receives `u + V0`. Already
    /// folded into [`Model::forces`]; kept here for reporting.
    Offset(Expr),
    /// `actuator u = input_delay(Td)`: the plant receives `u(t - Td)`, with
    /// `Td` (s) an expression over parameters. Not in the forces.
    Delay(Expr),
    /// `actuator u = deadzone(w)`: the plant receives
    /// `sign(u) * max(|u| - w, 0)`, with `w >= 0` (the input's unit) an
    /// expression over parameters. Not in the forces (they must stay linear
    /// in the inputs).
    Deadzone(Expr),
    /// `actuator u = saturation(L)`: the plant receives `min(max(u, -L), L)`,
    /// with `L > 0` (the input's unit) an expression over parameters (a
    /// drive's voltage or current limit). Not in the forces. At most one per
    /// input (the checker refuses a second).
    Saturation(Expr),
}

/// An effect on one input (`actuator u = ...`).
#[derive(Clone, Debug, PartialEq)]
pub struct ActuatorEffect {
    /// Index of the input in [`Model::inputs`].
    pub input: usize,
    /// The effect with its parameter expression.
    pub effect: ActuatorEffectKind,
}

/// A mechanical model: Lagrangian `T - V`, generalised forces, inputs, outputs.
///
/// # Sensor and actuator effects
/// `actuator u = input_offset(V0)` is folded into [`Model::forces`] at
/// lowering (every `u` becomes `u + V0`), so mechanics, linearization, code
/// generation and simulation see it with no change; so is `inertia q =
/// added_inertia(J)`, whose `1/2*J*q'^2` is added to [`Model::kinetic`].
/// `sensor q = sensor_offset(d)`, `actuator u = input_delay(Td)`,
/// `actuator u = deadzone(w)` and `actuator u = saturation(L)` cannot be
/// folded into the equations of motion (the forces must stay linear in the
/// inputs): they are listed in [`Model::sensors`] and [`Model::actuators`],
/// and only consumers that compare with measurements honour them
/// (identification's experiment simulation and sensitivities in
/// `plantc-identify`: measurement `q + d`, input `sat(dz(u))(t - Td) + V0`
/// with a zero-order hold: the deadzone acts on the commanded value, the
/// saturation on its result, the delay then shifts it in time, the offset is
/// in the forces). The state-space equations, `plantc sim`, linearization
/// and code generation describe the plant itself: they ignore both, and
/// [`Model::ignored_signal_effects`] names what they ignore so a command can
/// warn.
#[derive(Clone, Debug)]
pub struct Model {
    /// Model name.
    pub name: String,
    /// Description.
    pub description: Option<String>,
    /// Generalised coordinates in declaration order (state order is
    /// `q_1..q_n, q_1'..q_n'`).
    pub coordinates: Vec<Coordinate>,
    /// Inputs in declaration order.
    pub inputs: Vec<Input>,
    /// Outputs in declaration order.
    pub outputs: Vec<Output>,
    /// Parameters in declaration order.
    pub parameters: Vec<Parameter>,
    /// Parameter-only definitions in dependency order.
    pub derived: Vec<Derived>,
    /// Named parameter sets.
    pub sets: Vec<ParameterSet>,
    /// Kinetic energy `T(q, q')` (with the `added_inertia` terms of the
    /// `inertia` lines).
    pub kinetic: Expr,
    /// Potential energy `V(q)`.
    pub potential: Expr,
    /// Generalised force on each coordinate, `Q_i(q, q', u)` (input offsets
    /// folded in).
    pub forces: Vec<Expr>,
    /// Measurement effects (`sensor` lines), in file order.
    pub sensors: Vec<SensorEffect>,
    /// Input effects (`actuator` lines), in file order.
    pub actuators: Vec<ActuatorEffect>,
    /// Controllers declared in the file.
    pub controllers: Vec<ControllerSpec>,
    /// Controllers that ran while data were recorded.
    pub recorded: Vec<RecordedController>,
}

impl Model {
    /// Coordinate symbols in order.
    pub fn coordinate_symbols(&self) -> Vec<CoordinateSymbols> {
        self.coordinates.iter().map(|c| c.symbols).collect()
    }

    /// State symbols `q_1..q_n, q_1'..q_n'`.
    pub fn state_symbols(&self) -> Vec<Symbol> {
        let mut v: Vec<Symbol> = self.coordinates.iter().map(|c| c.symbols.q).collect();
        v.extend(self.coordinates.iter().map(|c| c.symbols.qd));
        v
    }

    /// State names as used in data files: `theta, alpha, theta_dot, alpha_dot`.
    pub fn state_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self.coordinates.iter().map(|c| c.name.clone()).collect();
        v.extend(self.coordinates.iter().map(|c| format!("{}_dot", c.name)));
        v
    }

    /// Input symbols in order.
    pub fn input_symbols(&self) -> Vec<Symbol> {
        self.inputs.iter().map(|i| i.symbol).collect()
    }

    /// Parameter symbols followed by derived-quantity symbols: the order of
    /// [`ParameterValues::full`].
    pub fn parameter_symbols(&self) -> Vec<Symbol> {
        let mut v: Vec<Symbol> = self.parameters.iter().map(|p| p.symbol).collect();
        v.extend(self.derived.iter().map(|d| d.symbol));
        v
    }

    /// Replace derived quantities by their definitions (recursively), leaving an
    /// expression over base parameters only.
    pub fn expand_derived(&self, e: Expr) -> Expr {
        let mut map = std::collections::HashMap::new();
        for d in &self.derived {
            let def = crate::sym::substitute_symbols(d.expr, &map);
            map.insert(d.symbol, def);
        }
        crate::sym::substitute_symbols(e, &map)
    }

    /// The total sensor offset of coordinate `i` (sum of its
    /// `sensor_offset` lines; zero without any), over parameters.
    pub fn sensor_offset(&self, i: usize) -> Expr {
        self.sensors
            .iter()
            .filter(|s| s.coordinate == i)
            .map(|s| match &s.effect {
                SensorEffectKind::Offset(d) => *d,
            })
            .sum()
    }

    /// The total delay of input `j` (sum of its `input_delay` lines, since
    /// delays compose; zero without any), over parameters.
    pub fn input_delay(&self, j: usize) -> Expr {
        self.actuators
            .iter()
            .filter(|a| a.input == j)
            .filter_map(|a| match &a.effect {
                ActuatorEffectKind::Delay(d) => Some(*d),
                ActuatorEffectKind::Offset(_)
                | ActuatorEffectKind::Deadzone(_)
                | ActuatorEffectKind::Saturation(_) => None,
            })
            .sum()
    }

    /// The total deadzone half-width of input `j` (sum of its `deadzone`
    /// lines, since `dz_w2(dz_w1(u)) = dz_(w1 + w2)(u)`; zero without any),
    /// over parameters.
    pub fn input_deadzone(&self, j: usize) -> Expr {
        self.actuators
            .iter()
            .filter(|a| a.input == j)
            .filter_map(|a| match &a.effect {
                ActuatorEffectKind::Deadzone(w) => Some(*w),
                ActuatorEffectKind::Offset(_)
                | ActuatorEffectKind::Delay(_)
                | ActuatorEffectKind::Saturation(_) => None,
            })
            .sum()
    }

    /// The saturation level of input `j` (its `saturation` line), if any,
    /// over parameters.
    pub fn input_saturation(&self, j: usize) -> Option<Expr> {
        self.actuators
            .iter()
            .filter(|a| a.input == j)
            .find_map(|a| match &a.effect {
                ActuatorEffectKind::Saturation(l) => Some(*l),
                _ => None,
            })
    }

    /// Whether any input has a `deadzone` line.
    pub fn has_deadzone(&self) -> bool {
        self.actuators
            .iter()
            .any(|a| matches!(a.effect, ActuatorEffectKind::Deadzone(_)))
    }

    /// Effects that the plant equations cannot hold (sensor offsets, input
    /// delays, deadzones and saturations), as `sensor alpha = sensor_offset(...)`-like labels:
    /// consumers other than identification ignore them and may warn with
    /// this list. Empty for most models.
    pub fn ignored_signal_effects(&self) -> Vec<String> {
        let mut v = Vec::new();
        for s in &self.sensors {
            let name = &self.coordinates[s.coordinate].name;
            match &s.effect {
                SensorEffectKind::Offset(d) => {
                    v.push(format!("sensor {name} = sensor_offset({d})"))
                }
            }
        }
        for a in &self.actuators {
            let name = &self.inputs[a.input].name;
            match &a.effect {
                ActuatorEffectKind::Delay(d) => {
                    v.push(format!("actuator {name} = input_delay({d})"))
                }
                ActuatorEffectKind::Deadzone(w) => {
                    v.push(format!("actuator {name} = deadzone({w})"))
                }
                ActuatorEffectKind::Saturation(l) => {
                    v.push(format!("actuator {name} = saturation({l})"))
                }
                ActuatorEffectKind::Offset(_) => {}
            }
        }
        v
    }

    /// Find a parameter by name.
    pub fn parameter(&self, name: &str) -> Option<&Parameter> {
        self.parameters.iter().find(|p| p.name == name)
    }

    /// Find a controller by name.
    pub fn controller(&self, name: &str) -> Option<&ControllerSpec> {
        self.controllers.iter().find(|c| c.name() == name)
    }

    /// Find a recorded controller by name.
    pub fn recorded_controller(&self, name: &str) -> Option<&RecordedController> {
        self.recorded.iter().find(|c| c.name == name)
    }
}
