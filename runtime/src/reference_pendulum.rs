//! Hand-written reference model of the Quanser SRV02 + ROTPEN rotary pendulum.
//!
//! This is the physics of the runtime's test doubles (the simulator in the
//! tests and the fake HIL library), written by hand from the thesis'
//! equations (the same model as `models/rotary_pendulum.plant`) so the
//! runtime has physics of its own, independent of derive and codegen. Convention: `x = [theta, alpha, theta_dot,
//! alpha_dot]`, `u = [Vm]`, `alpha = 0` upright (pendulum-up), hanging = ±pi.
//!
//! Equations (Cassolato & Prime form), with `J0h = J1 + m1 l1² + m2 L1²`,
//! `J2h = J2 + m2 l2²`, `c = m2 L1 l2`:
//!
//! ```text
//! (J0h + J2h sin²a) th'' - c cos(a) a'' = tau - b1 th' - 2 J2h sin(a)cos(a) th' a' - c sin(a) a'²
//! -c cos(a) th'' + J2h a''              = -b2 a' + J2h sin(a)cos(a) th'² + m2 g l2 sin(a)
//! tau = eta_g Kg eta_m kt (Vm - Kg km th') / Rm
//! ```
//!
//! The 2x2 mass matrix is inverted in closed form.

use crate::plant::Plant;

/// Physical parameters (Table 1 and Table 3 of the thesis, Quanser values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PendulumParams {
    /// Arm mass (kg).
    pub m1: f64,
    /// Arm length, pivot to tip (m).
    pub big_l1: f64,
    /// Arm pivot to centre of mass (m).
    pub l1: f64,
    /// Arm inertia about its centre of mass (kg m²).
    pub j1: f64,
    /// Pendulum mass (kg).
    pub m2: f64,
    /// Pendulum pivot to centre of mass (m).
    pub l2: f64,
    /// Pendulum inertia about its centre of mass (kg m²).
    pub j2: f64,
    /// Arm viscous damping (N m s/rad).
    pub b1: f64,
    /// Pendulum viscous damping (N m s/rad).
    pub b2: f64,
    /// Gravity (m/s²).
    pub g: f64,
    /// Gear ratio.
    pub kg: f64,
    /// Motor torque constant (N m/A).
    pub kt: f64,
    /// Motor back-EMF constant (V s/rad).
    pub km: f64,
    /// Motor efficiency.
    pub eta_m: f64,
    /// Gearbox efficiency.
    pub eta_g: f64,
    /// Armature resistance (ohm).
    pub rm: f64,
}

impl Default for PendulumParams {
    /// Table 1 / Table 3 values.
    fn default() -> Self {
        Self {
            m1: 0.257,
            big_l1: 0.216,
            l1: 0.0619,
            j1: 9.98e-4,
            m2: 0.127,
            l2: 0.156,
            j2: 0.0012,
            b1: 0.0024,
            b2: 0.0024,
            g: 9.81,
            kg: 70.0,
            kt: 7.68e-3,
            km: 7.68e-3,
            eta_m: 0.69,
            eta_g: 0.9,
            rm: 2.6,
        }
    }
}

const STATE_NAMES: &[&str] = &["theta", "alpha", "theta_dot", "alpha_dot"];
const INPUT_NAMES: &[&str] = &["Vm"];

/// The reference rotary pendulum (test double physics, pendulum-up convention).
#[derive(Debug, Clone, PartialEq)]
pub struct RotaryPendulumReference {
    /// Physical parameters.
    pub params: PendulumParams,
    /// Motor voltage limits `(min, max)`; default ±10 V (the Q2-USB's analog range).
    pub limits: [(f64, f64); 1],
}

impl Default for RotaryPendulumReference {
    fn default() -> Self {
        Self::new(PendulumParams::default())
    }
}

impl RotaryPendulumReference {
    /// A pendulum with the given parameters and ±10 V input limits.
    pub fn new(params: PendulumParams) -> Self {
        Self {
            params,
            limits: [(-10.0, 10.0)],
        }
    }
}

impl Plant for RotaryPendulumReference {
    fn state_names(&self) -> &[&str] {
        STATE_NAMES
    }

    fn input_names(&self) -> &[&str] {
        INPUT_NAMES
    }

    fn input_limits(&self) -> &[(f64, f64)] {
        &self.limits
    }

    fn derivatives(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        if x.len() < 4 || u.is_empty() || dx.len() < 4 {
            dx.fill(f64::NAN);
            return;
        }
        let (a, thd, ad, vm) = (x[1], x[2], x[3], u[0]);
        let p = &self.params;
        let j0h = p.j1 + p.m1 * p.l1 * p.l1 + p.m2 * p.big_l1 * p.big_l1;
        let j2h = p.j2 + p.m2 * p.l2 * p.l2;
        let c = p.m2 * p.big_l1 * p.l2;
        let (s, co) = a.sin_cos();
        let tau = p.eta_g * p.kg * p.eta_m * p.kt * (vm - p.kg * p.km * thd) / p.rm;
        // Mass matrix M = [[m11, m12], [m12, m22]].
        let m11 = j0h + j2h * s * s;
        let m12 = -c * co;
        let m22 = j2h;
        let r1 = tau - p.b1 * thd - 2.0 * j2h * s * co * thd * ad - c * s * ad * ad;
        let r2 = -p.b2 * ad + j2h * s * co * thd * thd + p.m2 * p.g * p.l2 * s;
        let det = m11 * m22 - m12 * m12;
        dx[0] = thd;
        dx[1] = ad;
        dx[2] = (m22 * r1 - m12 * r2) / det;
        dx[3] = (m11 * r2 - m12 * r1) / det;
    }
}
