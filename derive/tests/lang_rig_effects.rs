//! The effects real rigs need: `cogging(A, N[, phase])` and
//! `speed_limit(vmax, c)` (force terms), `actuator u = saturation(L)` and
//! `inertia q = added_inertia(J)`: parsing, printing back, lowering and
//! lossless editing. Reference values are the effects' definitions evaluated
//! here by hand (`-A sin(N q + phase)`, `-c (q' - clip(q', vmax))`, a model
//! with `1/2 J q'^2` written into `T`).

use std::collections::HashMap;

use plantc_derive::lang::edit::{add_actuator_effect, add_inertia_effect, EditError};
use plantc_derive::lang::parse_and_check;
use plantc_derive::mechanics::derive_equations;
use plantc_derive::model::{load_model_text, ActuatorEffectKind, Model};
use plantc_derive::sym::Symbol;

const MODEL: &str = "\
model arm \"a driven arm on a carriage\"
coordinate theta : angle
coordinate x : length
input Vm [V]
parameter J = 0.01 [kg*m^2]
parameter m = 1 [kg]
parameter k = 0.05 [N*m/V]
parameter A = 0.003 [N*m]
parameter N = 24
parameter ph = 0.4
parameter vmax = 2 [rad/s]
parameter c = 0.8 [N*m*s/rad]
parameter Jr = 2e-3 [kg*m^2]
parameter mr = 0.3 [kg]
parameter L = 5 [V]
kinetic T = 1/2*J*theta'^2 + 1/2*m*x'^2 + 1/2*m*0.1 [m]*cos(theta)*theta'*x'
potential V = 0 [J]
force theta = k*Vm + cogging(A, N, ph) + speed_limit(vmax, c)
force x = cogging(0.5 [N], 40 [1/m])
actuator Vm = saturation(L)
inertia theta = added_inertia(Jr)
inertia x = added_inertia(mr)   # a second body riding on the carriage
";

fn model(text: &str) -> Model {
    match load_model_text("m.plant", text) {
        Ok(m) => m.model,
        Err(e) => panic!("{}", e.render()),
    }
}

fn values(m: &Model, state: &[(&str, f64)]) -> HashMap<Symbol, f64> {
    m.parameters
        .iter()
        .map(|p| (p.symbol, p.value))
        .chain(state.iter().map(|(n, v)| (Symbol::new(n), *v)))
        .collect()
}

#[test]
fn lines_check_and_print_back() {
    let c = parse_and_check("m.plant", MODEL);
    assert!(!c.has_errors(), "{:?}", c.diagnostics);
    assert!(
        c.diagnostics
            .iter()
            .all(|d| d.code != "plantc::cogging_period"),
        "integer N and a length coordinate give no warning"
    );
    let file = c.model.unwrap();
    assert_eq!(file.inertias.len(), 2);
    assert_eq!(
        file.inertias[0].to_string(),
        "inertia theta = added_inertia(Jr)"
    );
    assert_eq!(file.actuators[0].to_string(), "actuator Vm = saturation(L)");
}

/// Cogging: `-A sin(N q + phase)` (and `-A sin(N q)` without the phase).
#[test]
fn cogging_is_the_periodic_force() {
    let m = model(MODEL);
    for &(theta, x) in &[(0.0, 0.0), (0.31, -0.02), (-2.0, 0.7)] {
        let v = values(
            &m,
            &[
                ("theta", theta),
                ("x", x),
                ("theta'", 0.0),
                ("x'", 0.0),
                ("Vm", 0.0),
            ],
        );
        let f = m.forces[0].eval_map(&v);
        let expected = -3e-3 * (24.0 * theta + 0.4).sin();
        assert!((f - expected).abs() < 1e-15, "{f} vs {expected}");
        let fx = m.forces[1].eval_map(&v);
        let expected = -0.5 * (40.0 * x).sin();
        assert!((fx - expected).abs() < 1e-15, "{fx} vs {expected}");
    }
}

/// The speed limit is zero at rest, odd, within `c*vmax/100` (half the
/// rounding width `vmax/50` times `c`) of `-c (q' - clip(q', vmax))`
/// everywhere, and equal to it up to `c*vmax*1e-3` away from the kinks.
#[test]
fn speed_limit_is_a_rounded_dead_band_damper() {
    let m = model(MODEL);
    let (vmax, c) = (2.0, 0.8);
    let exact = |v: f64| -c * (v - v.clamp(-vmax, vmax));
    let cog = |v: &HashMap<Symbol, f64>| {
        let th = v[&Symbol::new("theta")];
        -3e-3 * (24.0 * th + 0.4).sin()
    };
    let mut worst = 0.0f64;
    for i in -400..=400 {
        let w = i as f64 * 0.02; // -8 .. 8 rad/s
        let v = values(
            &m,
            &[
                ("theta", 0.2),
                ("x", 0.0),
                ("theta'", w),
                ("x'", 0.0),
                ("Vm", 0.0),
            ],
        );
        let f = m.forces[0].eval_map(&v) - cog(&v);
        let err = (f - exact(w)).abs();
        worst = worst.max(err);
        assert!(
            err <= c * vmax / 100.0 + 1e-12,
            "q' = {w}: {f} vs {}",
            exact(w)
        );
        if (w.abs() - vmax).abs() > 0.5 {
            assert!(err <= 1e-3 * c * vmax, "q' = {w}: {f} vs {}", exact(w));
        }
        let neg = values(
            &m,
            &[
                ("theta", 0.2),
                ("x", 0.0),
                ("theta'", -w),
                ("x'", 0.0),
                ("Vm", 0.0),
            ],
        );
        let g = m.forces[0].eval_map(&neg) - cog(&neg);
        assert!((f + g).abs() < 1e-12, "odd: {f} {g}");
    }
    let at_rest = values(
        &m,
        &[
            ("theta", 0.2),
            ("x", 0.0),
            ("theta'", 0.0),
            ("x'", 0.0),
            ("Vm", 0.0),
        ],
    );
    assert!((m.forces[0].eval_map(&at_rest) - cog(&at_rest)).abs() < 1e-15);
    eprintln!("speed limit: largest deviation from the sharp dead band {worst:.3e} N*m");
}

/// `added_inertia` adds `J` to the mass matrix diagonal of its coordinate:
/// the same equations as writing `1/2*J*q'^2` into `T` by hand.
#[test]
fn added_inertia_is_a_kinetic_energy_term() {
    let with = model(MODEL);
    let by_hand = MODEL
        .replace(
            "kinetic T = 1/2*J*theta'^2 + 1/2*m*x'^2",
            "kinetic T = 1/2*J*theta'^2 + 1/2*m*x'^2 + 1/2*Jr*theta'^2 + 1/2*mr*x'^2",
        )
        .replace("inertia theta = added_inertia(Jr)\n", "")
        .replace(
            "inertia x = added_inertia(mr)   # a second body riding on the carriage\n",
            "",
        );
    let hand = model(&by_hand);
    let (a, b) = (
        derive_equations(&with).unwrap(),
        derive_equations(&hand).unwrap(),
    );
    let v = values(
        &with,
        &[
            ("theta", 0.7),
            ("x", 0.1),
            ("theta'", 1.3),
            ("x'", -0.4),
            ("Vm", 1.0),
        ],
    );
    for i in 0..2 {
        for j in 0..2 {
            let (p, q) = (
                a.mass_matrix[i][j].eval_map(&v),
                b.mass_matrix[i][j].eval_map(&v),
            );
            assert!((p - q).abs() < 1e-15, "M[{i}][{j}]: {p} vs {q}");
        }
        let (p, q) = (a.bias[i].eval_map(&v), b.bias[i].eval_map(&v));
        assert!((p - q).abs() < 1e-15, "bias[{i}]: {p} vs {q}");
    }
    // and it is there: M_00 = J + Jr, M_11 = m + mr
    assert!((a.mass_matrix[0][0].eval_map(&v) - 0.012).abs() < 1e-15);
    assert!((a.mass_matrix[1][1].eval_map(&v) - 1.3).abs() < 1e-15);
    // not a signal effect: nothing for plant-equation consumers to ignore
    let loaded = load_model_text("m.plant", MODEL).unwrap();
    let warned: Vec<&str> = loaded
        .ignored_signal_effects("`plantc sim`")
        .iter()
        .map(|d| &MODEL[d.primary.start..d.primary.end])
        .collect();
    assert_eq!(warned, ["actuator Vm = saturation(L)"]);
}

/// `saturation(L)` stays out of the forces (they must stay linear in the
/// inputs) and is listed for identification.
#[test]
fn saturation_is_lowered_unfolded() {
    let m = model(MODEL);
    assert!(matches!(
        m.actuators[0].effect,
        ActuatorEffectKind::Saturation(_)
    ));
    let v = values(
        &m,
        &[
            ("theta", 0.0),
            ("x", 0.0),
            ("theta'", 0.0),
            ("x'", 0.0),
            ("Vm", 9.0),
        ],
    );
    assert_eq!(m.input_saturation(0).map(|l| l.eval_map(&v)), Some(5.0));
    assert!(!m.forces[0].contains(Symbol::new("L")));
    assert_eq!(
        m.ignored_signal_effects(),
        vec!["actuator Vm = saturation(L)".to_string()]
    );
    let plain = model(&MODEL.replace("actuator Vm = saturation(L)\n", ""));
    assert!(plain.input_saturation(0).is_none());
}

fn without_lines() -> String {
    MODEL
        .lines()
        .filter(|l| !l.starts_with("inertia") && !l.starts_with("actuator"))
        .map(|l| format!("{l}\n"))
        .collect()
}

#[test]
fn add_inertia_effect_appends_one_line() {
    let src = without_lines();
    let out = add_inertia_effect(&src, "theta", "added_inertia(Jr)").unwrap();
    let at = src.len();
    assert_eq!(&out[..at], src, "everything before is kept");
    assert_eq!(&out[at..], "inertia theta = added_inertia(Jr)\n");
    let m = model(&out);
    let v = values(&m, &[("theta", 0.0), ("x", 0.0)]);
    let eqs = derive_equations(&m).unwrap();
    assert!((eqs.mass_matrix[0][0].eval_map(&v) - 0.012).abs() < 1e-15);
    // CRLF and comments are kept
    let crlf = src.replace('\n', "\r\n");
    let out = add_inertia_effect(&crlf, "x", "added_inertia(mr)").unwrap();
    assert!(
        out.ends_with("inertia x = added_inertia(mr)\r\n"),
        "{out:?}"
    );
    // refused: an input, an unknown coordinate, a wrong unit, a force effect
    assert!(matches!(
        add_inertia_effect(&src, "Vm", "added_inertia(Jr)"),
        Err(EditError::UnknownCoordinate { .. })
    ));
    assert!(matches!(
        add_inertia_effect(&src, "thetaa", "added_inertia(Jr)"),
        Err(EditError::UnknownCoordinate { .. })
    ));
    assert!(matches!(
        add_inertia_effect(&src, "theta", "added_inertia(m)"),
        Err(EditError::WouldBreak(_))
    ));
    assert!(matches!(
        add_inertia_effect(&src, "theta", "viscous_friction(c)"),
        Err(EditError::WouldBreak(_))
    ));
    // a saturation through the actuator editor; a second one is refused
    let sat = add_actuator_effect(&src, "Vm", "saturation(L)").unwrap();
    assert!(sat.ends_with("actuator Vm = saturation(L)\n"));
    assert!(matches!(
        add_actuator_effect(&sat, "Vm", "saturation(2*L)"),
        Err(EditError::WouldBreak(_))
    ));
}
