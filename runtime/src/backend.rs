//! The hardware abstraction the control loop drives: encoders in, one motor
//! voltage out, a sample clock and a watchdog.

use std::f64::consts::PI;
use std::fmt;

/// How one encoder's counts map to a state angle:
/// `angle = sign * counts * 2 pi / counts_per_rev + offset_rad`, then wrapped
/// into `(-pi, pi]` if `wrap` is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderMap {
    /// Counts per revolution (4096 for the SRV02/ROTPEN quadrature encoders).
    pub counts_per_rev: f64,
    /// +1 or -1.
    pub sign: f64,
    /// Angle at zero counts (e.g. pi for a pendulum zeroed while hanging).
    pub offset_rad: f64,
    /// Wrap the angle into `(-pi, pi]` (for the pendulum, so upright is 0 whichever way it was raised).
    pub wrap: bool,
}

impl EncoderMap {
    /// A plain map: `counts_per_rev`, sign +1, no offset, no wrapping.
    pub fn plain(counts_per_rev: f64) -> Self {
        Self {
            counts_per_rev,
            sign: 1.0,
            offset_rad: 0.0,
            wrap: false,
        }
    }

    /// The continuous (unwrapped) angle for `counts`; used for differentiation.
    pub fn angle_unwrapped(&self, counts: i32) -> f64 {
        self.sign * f64::from(counts) * 2.0 * PI / self.counts_per_rev + self.offset_rad
    }

    /// The state angle for `counts` (wrapped if configured).
    pub fn angle(&self, counts: i32) -> f64 {
        self.angles(counts).0
    }

    /// The state angle and the unwrapped angle for `counts`, the counts
    /// converted once (the loop needs both every sample).
    pub fn angles(&self, counts: i32) -> (f64, f64) {
        let a = self.angle_unwrapped(counts);
        (if self.wrap { wrap_pi(a) } else { a }, a)
    }
}

/// Wraps an angle into `(-pi, pi]`.
pub fn wrap_pi(a: f64) -> f64 {
    if !a.is_finite() {
        return a;
    }
    let mut r = a.rem_euclid(2.0 * PI);
    if r > PI {
        r -= 2.0 * PI;
    }
    r
}

/// One sample instant reported by [`Backend::wait_next_period`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// Time of this sample on the backend's clock, seconds since start.
    pub t: f64,
    /// Sample instants that were skipped because the loop was late (0 normally).
    pub missed: u32,
}

/// Errors of a backend. Small, with the data needed to diagnose them.
#[derive(Debug, Clone, PartialEq)]
pub enum BackendError {
    /// A HIL function returned an error code (message from `msg_get_error_messageA`).
    Hil {
        /// The C function that failed.
        function: &'static str,
        /// The HIL error code (negative).
        code: i32,
        /// Quanser's message for the code, or a fallback text.
        message: String,
    },
    /// The board watchdog expired (outputs went to the 0 V expiration state).
    WatchdogExpired,
    /// The board refused to arm the watchdog and no override was given.
    WatchdogRefused {
        /// The HIL error code.
        code: i32,
        /// Quanser's message for the code.
        message: String,
    },
    /// The HIL library could not be loaded.
    Load {
        /// Library path or name that was tried.
        path: String,
        /// The loader's reason.
        reason: String,
    },
    /// A required symbol is missing from the HIL library.
    MissingSymbol(&'static str),
    /// The configuration is unusable.
    InvalidConfig(String),
    /// A call that needs `start` first.
    NotStarted,
    /// The backend was already closed.
    Closed,
    /// Stopping the board safely met errors: every failed call in order
    /// (failed 0 V writes included, none dropped) and what holds the output
    /// now. Returned by [`Backend::close`] (and by an open that failed and
    /// could not close cleanly).
    SafeStop {
        /// The failed calls, in order.
        failures: Vec<BackendError>,
        /// What holds the output after them.
        output: OutputHold,
    },
    /// The simulated plant's state is no longer finite (NaN or infinite):
    /// the simulation diverged (stiff or unstable parameters, a huge initial
    /// state). Real encoders cannot report this.
    PlantDiverged {
        /// Simulated time (s).
        t: f64,
        /// The state, named: `alpha = NaN, theta = 3.2e308, ...`.
        state: String,
    },
}

impl fmt::Display for BackendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BackendError::Hil {
                function,
                code,
                message,
            } => write!(f, "{function} failed with HIL error {code}: {message}"),
            BackendError::WatchdogExpired => write!(f, "the board watchdog expired"),
            BackendError::WatchdogRefused { code, message } => write!(
                f,
                "the board refused the watchdog expiration state (HIL error {code}: {message}); \
                 refusing to drive the motor without a hardware watchdog (override: allow_no_watchdog)"
            ),
            BackendError::Load { path, reason } => {
                write!(f, "cannot load HIL library {path}: {reason}")
            }
            BackendError::MissingSymbol(s) => write!(f, "HIL library lacks symbol {s}"),
            BackendError::InvalidConfig(s) => write!(f, "invalid backend configuration: {s}"),
            BackendError::NotStarted => write!(f, "backend not started"),
            BackendError::Closed => write!(f, "backend already closed"),
            BackendError::SafeStop { failures, output } => {
                write!(f, "stopping the board: ")?;
                for (i, e) in failures.iter().enumerate() {
                    if i > 0 {
                        write!(f, "; ")?;
                    }
                    write!(f, "{e}")?;
                }
                write!(f, "; {output}")
            }
            BackendError::PlantDiverged { t, state } => write!(
                f,
                "the simulated plant diverged at t = {t} s (state no longer finite: {state}); \
                 check the parameter values (a tiny mass, inertia or resistance makes the model stiff) \
                 and the initial state"
            ),
        }
    }
}

impl std::error::Error for BackendError {}

/// What holds a board's output once its backend stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OutputHold {
    /// A 0 V write was confirmed by the board (and nothing was written after it).
    ZeroConfirmed,
    /// The watchdog had expired: the output is in its 0 V expiration state.
    WatchdogExpired,
    /// No 0 V write was confirmed; the board was left open with its watchdog
    /// armed (expiration state 0 V, not reloaded any more): it drives the
    /// output to 0 V within `timeout_s` of its last reload.
    WatchdogArmed {
        /// The watchdog's timeout (s).
        timeout_s: f64,
    },
    /// No 0 V write was confirmed and no watchdog could be armed: the output
    /// may still be at the last voltage the board accepted.
    Unknown {
        /// The last voltage the board accepted (V).
        last_volts: f64,
    },
}

impl OutputHold {
    /// Whether the output is known to be at 0 V now or to get there by itself.
    pub fn is_safe(self) -> bool {
        !matches!(self, OutputHold::Unknown { .. })
    }
}

impl fmt::Display for OutputHold {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OutputHold::ZeroConfirmed => write!(f, "the output is at 0 V (write confirmed)"),
            OutputHold::WatchdogExpired => {
                write!(
                    f,
                    "the watchdog expired: the output is in its 0 V expiration state"
                )
            }
            OutputHold::WatchdogArmed { timeout_s } => write!(
                f,
                "no 0 V write was confirmed: the board is left open with its watchdog armed \
                 (expiration state 0 V, no longer reloaded), which drives the output to 0 V \
                 within {timeout_s} s"
            ),
            OutputHold::Unknown { last_volts } if last_volts.is_nan() => write!(
                f,
                "no 0 V write was confirmed and no hardware watchdog is armed: the output is \
                 where it was before the board was opened; switch the amplifier off"
            ),
            OutputHold::Unknown { last_volts } => write!(
                f,
                "no 0 V write was confirmed and no hardware watchdog is armed: the output may \
                 still be at {last_volts:.3} V; switch the amplifier off"
            ),
        }
    }
}

/// A data-acquisition backend: the simulator or a Quanser board.
///
/// Call order: [`Backend::start`] once, then per sample
/// [`Backend::wait_next_period`], [`Backend::read_encoders`],
/// [`Backend::reload_watchdog`], [`Backend::write_voltage`]; finally
/// [`Backend::close`], which must write 0 V and be idempotent. Implementations
/// must also write 0 V when dropped without `close`. Per-sample calls must not
/// allocate except to report an error. A `close` that cannot confirm 0 V
/// returns [`BackendError::SafeStop`] naming every failed call and leaves
/// whatever hardware fallback it has (a watchdog) armed.
pub trait Backend {
    /// The encoder-to-angle maps, one per encoder, in state order (positions).
    fn encoders(&self) -> &[EncoderMap];
    /// Whether the clock is virtual (the loop runs as fast as it can).
    fn is_virtual_time(&self) -> bool;
    /// Starts the sample clock with the given period (seconds) and arms the watchdog.
    fn start(&mut self, period_s: f64) -> Result<(), BackendError>;
    /// Blocks until the next sample instant and returns it. The first call returns t = 0.
    fn wait_next_period(&mut self) -> Result<Tick, BackendError>;
    /// Encoder counts at the current sample, one per encoder.
    fn read_encoders(&mut self, counts: &mut [i32]) -> Result<(), BackendError>;
    /// Writes the motor voltage (already clamped by the loop).
    fn write_voltage(&mut self, volts: f64) -> Result<(), BackendError>;
    /// Reloads the hardware watchdog; [`BackendError::WatchdogExpired`] if it had expired.
    fn reload_watchdog(&mut self) -> Result<(), BackendError> {
        Ok(())
    }
    /// Stops the clock, writes 0 V and releases the hardware. Idempotent
    /// once it has succeeded; an error lists every failed call.
    fn close(&mut self) -> Result<(), BackendError>;
}
