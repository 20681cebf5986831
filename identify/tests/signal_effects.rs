//! Sensor and actuator effects in the experiment simulation and its
//! sensitivities, and as diagnose/synth candidates. Reference values come
//! from the simulator itself on transformed data (offset input, shifted
//! input, shifted measurement), from central finite differences of the plain
//! simulation, or from the closed form of a point mass under a held force.

mod common;

use common::simulated::{driven_signals, max_diff, model, pendulum_text, pendulum_with, simulate};

use plantc_derive::model::{load_model_text, Model, ParameterValues};
use plantc_identify::effect_edit::all_candidates;
use plantc_identify::{
    EffectEditError, EffectInstance, EffectKind, SensitivitySimulator, Signals, SimError,
    SimOptions, Simulator,
};

#[test]
fn input_offset_equals_offset_input() {
    let with = pendulum_with("parameter V0 = 0.37 [V]\nactuator Vm = input_offset(V0)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    let mut shifted = sig.clone();
    shifted.u[0].iter_mut().for_each(|u| *u += 0.37);
    let d = max_diff(&simulate(&with, &sig), &simulate(&base, &shifted));
    eprintln!("input offset: max difference {d:.2e}");
    assert!(d < 1e-12, "{d}");
    // and the offset does change the motion
    assert!(max_diff(&simulate(&with, &sig), &simulate(&base, &sig)) > 1e-3);
}

#[test]
fn sensor_offset_simulates_q_plus_d() {
    let d = 0.05;
    let with = pendulum_with("parameter d = 0.05 [rad]\nsensor alpha = sensor_offset(d)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    // the true initial angle is the measured one minus d
    let mut truth = sig.clone();
    truth.q[1].iter_mut().for_each(|q| *q -= d);
    let mut expected = simulate(&base, &truth);
    expected[1].iter_mut().for_each(|q| *q += d);
    let diff = max_diff(&simulate(&with, &sig), &expected);
    eprintln!("sensor offset: max difference {diff:.2e}");
    assert!(diff < 1e-12, "{diff}");
}

#[test]
fn delay_of_one_sample_equals_shifted_input() {
    let with = pendulum_with("parameter Td = 0.002 [s]\nactuator Vm = input_delay(Td)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    let mut shifted = sig.clone();
    let u = &sig.u[0];
    shifted.u[0] = (0..u.len()).map(|k| u[k.saturating_sub(1)]).collect();
    let d = max_diff(&simulate(&with, &sig), &simulate(&base, &shifted));
    eprintln!("one-sample delay: max difference {d:.2e}");
    assert!(d < 1e-12, "{d}");
    // a zero delay is the nominal simulation, bit for bit
    let zero = pendulum_with("parameter Td = 0 [s]\nactuator Vm = input_delay(Td)\n");
    assert_eq!(simulate(&zero, &sig), simulate(&base, &sig));
}

const MASS: &str = "model mass \"point mass\"\ncoordinate x : length\ninput F [N]\n\
                    parameter m = 2 [kg]\nparameter Td = 0.0037 [s] estimate [0, 0.05]\n\
                    parameter dx = 0.01 [m] estimate [-0.2, 0.2]\n\
                    kinetic T = 1/2*m*x'^2\nforce x = F\n\
                    actuator F = input_delay(Td)\nsensor x = sensor_offset(dx)\n";

fn mass_signals() -> Signals {
    let t: Vec<f64> = (0..50).map(|k| k as f64 * 0.01).collect();
    let f: Vec<f64> = (0..50).map(|k| ((k * 7) % 5) as f64 - 2.0).collect();
    Signals {
        name: "steps".into(),
        t,
        q: vec![vec![0.3; 50]],
        u: vec![f],
        replay: None,
    }
}

/// `m x'' = F(t - Td)`, F held: x is piecewise quadratic between the
/// switch instants `t_k + Td`, which RK4 integrates exactly when steps are
/// split there, so the simulation matches the closed form to rounding.
#[test]
fn delayed_point_mass_matches_closed_form() {
    let m = model(MASS);
    let sig = mass_signals();
    let q = simulate(&m, &sig);
    let (td, dx, mass) = (0.0037, 0.01, 2.0);
    let f = &sig.u[0];
    // exact: integrate piece by piece over the switch grid
    let (mut x, mut v, mut t) = (0.3 - dx, 0.0, 0.0);
    let mut active = f[0];
    let mut next = 1; // next sample whose value switches in
    for (k, &qk) in q[0].iter().enumerate() {
        assert!((qk - (x + dx)).abs() < 1e-12, "k={k}: {} vs {}", qk, x + dx);
        let t_end = k as f64 * 0.01 + 0.01;
        while t < t_end {
            let s = if next < 50 {
                next as f64 * 0.01 + td
            } else {
                f64::INFINITY
            };
            let b = s.min(t_end);
            let (h, a) = (b - t, active / mass);
            x += v * h + 0.5 * a * h * h;
            v += a * h;
            t = b;
            if b == s {
                active = f[next];
                next += 1;
            }
        }
    }
}

/// Sensitivities against central differences of the plain simulation.
fn check_sensitivities(m: &Model, sig: &Signals, free: &[&str], steps: &[f64], tol: &[f64]) {
    let free: Vec<String> = free.iter().map(|s| s.to_string()).collect();
    let sens = SensitivitySimulator::new(m, &free, SimOptions::default()).expect("compiles");
    let sim = Simulator::new(m, SimOptions::default()).expect("compiles");
    let base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    let st = sens
        .simulate(
            sig,
            &ParameterValues::from_base(m, base.clone()).full,
            sig.len(),
        )
        .expect("simulates");
    let plain = sim
        .simulate(
            sig,
            &ParameterValues::from_base(m, base.clone()).full,
            sig.len(),
        )
        .expect("simulates");
    assert!(max_diff(&st.q, &plain.q) < 1e-12);
    let n = m.coordinates.len();
    for (j, &pi) in sens.free_indices().iter().enumerate() {
        let h = steps[j];
        let run = |delta: f64| {
            let mut b = base.clone();
            b[pi] += delta;
            sim.simulate(sig, &ParameterValues::from_base(m, b).full, sig.len())
                .expect("simulates")
        };
        let (yp, ym) = (run(h), run(-h));
        for i in 0..n {
            let scale = st.dq[i][j].iter().fold(1e-12_f64, |a, v| a.max(v.abs()));
            let mut worst = 0.0_f64;
            for k in 0..sig.len() {
                let fd = (yp.q[i][k] - ym.q[i][k]) / (2.0 * h);
                worst = worst.max((fd - st.dq[i][j][k]).abs());
            }
            eprintln!(
                "{} coord {i}: max |S| {scale:.3e}, max error {worst:.3e} ({:.1e} relative)",
                free[j],
                worst / scale
            );
            assert!(worst <= tol[j] * scale, "{} coord {i}", free[j]);
        }
    }
}

/// The point mass is integrated exactly (see above), so the delay
/// sensitivity must match the differences up to their own error (the
/// position is quadratic in Td between crossings: central differences are
/// exact up to rounding, ~1e-16/h).
#[test]
fn point_mass_delay_and_offset_sensitivities() {
    let m = model(MASS);
    check_sensitivities(
        &m,
        &mass_signals(),
        &["Td", "dx"],
        &[1e-7, 1e-6],
        &[1e-6, 1e-9],
    );
}

/// Pendulum with all three effects (and its stiff smoothed dry friction).
/// The sensitivities are exact derivatives of the discrete simulation,
/// including the delay's (segments in scaled time, see sensitivity.rs), so
/// 1e-4 relative only covers the finite differences' own truncation and
/// rounding, as in tests/sensitivity.rs (measured: about 1e-7). The delay
/// 1.3 ms with 1 ms substeps keeps every segment's substep count fixed under
/// the +-1e-7 s perturbation (the count is piecewise constant in Td).
#[test]
fn pendulum_sensitivities_to_offset_input_offset_and_delay() {
    let m = pendulum_with(
        "parameter d_alpha = 0.02 [rad] estimate [-0.2, 0.2]\n\
         parameter V0_Vm = 0.2 [V] estimate [-1, 1]\n\
         parameter Td_Vm = 0.0013 [s] estimate [0, 0.05]\n\
         sensor alpha = sensor_offset(d_alpha)\n\
         actuator Vm = input_offset(V0_Vm)\n\
         actuator Vm = input_delay(Td_Vm)\n",
    );
    check_sensitivities(
        &m,
        &driven_signals(),
        &["d_alpha", "V0_Vm", "Td_Vm", "J1"],
        &[1e-6, 1e-6, 1e-7, 1e-8],
        &[1e-4; 4],
    );
}

/// The checker refuses a negative delay in the file; a fit or a caller can
/// still pass one in the parameter vector: an error, not a panic.
#[test]
fn negative_delay_is_an_error() {
    assert!(load_model_text(
        "neg.plant",
        &(pendulum_text() + "\nparameter Td = -0.001 [s]\nactuator Vm = input_delay(Td)\n")
    )
    .is_err());
    let m = pendulum_with("parameter Td = 0.001 [s]\nactuator Vm = input_delay(Td)\n");
    let mut base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    let i = m
        .parameters
        .iter()
        .position(|p| p.name == "Td")
        .expect("Td");
    base[i] = -0.001;
    let sig = driven_signals();
    let r = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .simulate(&sig, &ParameterValues::from_base(&m, base).full, sig.len());
    match r {
        Err(e @ SimError::BadDelay { .. }) => {
            assert!(e.to_string().contains("`Vm`"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn effect_candidates_on_sensors_and_inputs() {
    let text = pendulum_text();
    let m = model(&text);
    let cs = all_candidates(&m);
    let labels: Vec<String> = cs.iter().map(|c| c.label()).collect();
    for l in [
        "sensor_offset@theta",
        "sensor_offset@alpha",
        "input_offset@Vm",
        "input_delay@Vm",
    ] {
        assert!(labels.contains(&l.to_string()), "{labels:?}");
    }
    assert!(!labels.iter().any(|l| l.starts_with("sensor_offset@Vm")));
    for c in &cs {
        let edited = c.apply(&text).expect("applies");
        let e = model(&edited);
        assert_eq!(e.parameters.len(), m.parameters.len() + c.parameters.len());
    }
    let d = EffectInstance::candidate(&m, "sensor_offset", "alpha").expect("candidate");
    assert_eq!(d.kind, EffectKind::Sensor);
    assert_eq!(
        d.snippet(),
        "parameter d_alpha = 0 [rad] \"sensor_offset@alpha\" estimate [-0.2, 0.2]\n\
         sensor alpha = sensor_offset(d_alpha)\n"
    );
    let v0 = EffectInstance::candidate(&m, "input_offset", "Vm").expect("candidate");
    assert_eq!(v0.parameters[0].unit, "V");
    assert_eq!(v0.parameters[0].estimate, Some((-1.0, 1.0)));
    let td = EffectInstance::with_values(&m, "input_delay", "Vm", &[("Td".into(), 0.004)])
        .expect("instance");
    let edited = td.apply(&text).expect("applies");
    assert!(
        edited.ends_with("actuator Vm = input_delay(Td_Vm)\n")
            || edited.contains("\nactuator Vm = input_delay(Td_Vm)\n")
    );
    let e = model(&edited);
    let delay = e
        .input_delay(0)
        .eval_map(&e.parameters.iter().map(|p| (p.symbol, p.value)).collect());
    assert!((delay - 0.004).abs() < 1e-15);
    match EffectInstance::candidate(&m, "input_delay", "alpha") {
        Err(EffectEditError::UnknownTarget { valid, .. }) => assert_eq!(valid, ["Vm"]),
        other => panic!("{other:?}"),
    }
    match EffectInstance::candidate(&m, "sensor_offset", "Vm") {
        Err(EffectEditError::UnknownTarget { valid, .. }) => assert_eq!(valid, ["theta", "alpha"]),
        other => panic!("{other:?}"),
    }
}

/// Noise-free data from the pendulum with hidden offset, input offset and
/// delay; a fit of the three from other starts recovers the true values
/// (the data are the model's own simulation, so the optimum is exact).
#[test]
fn fit_recovers_hidden_offsets_and_delay() {
    use plantc_identify::data::{Channel, Experiment};
    use plantc_identify::{fit, FitOptions};
    let lines = |d: &str, v0: &str, td: &str, est: bool| {
        let e = |b: &str| {
            if est {
                format!(" estimate {b}")
            } else {
                String::new()
            }
        };
        format!(
            "parameter d_alpha = {d} [rad]{}\nparameter V0_Vm = {v0} [V]{}\n\
             parameter Td_Vm = {td} [s]{}\nsensor alpha = sensor_offset(d_alpha)\n\
             actuator Vm = input_offset(V0_Vm)\nactuator Vm = input_delay(Td_Vm)\n",
            e("[-0.2, 0.2]"),
            e("[-1, 1]"),
            e("[0, 0.05]")
        )
    };
    let truth = pendulum_with(&lines("0.03", "0.15", "0.0042", false));
    let sig = driven_signals();
    let q = simulate(&truth, &sig);
    let exp = Experiment {
        name: "hidden".into(),
        file: "hidden.csv".into(),
        t: sig.t.clone(),
        channels: vec![
            Channel {
                name: "theta".into(),
                unit_note: None,
                values: q[0].clone(),
            },
            Channel {
                name: "alpha".into(),
                unit_note: None,
                values: q[1].clone(),
            },
            Channel {
                name: "Vm".into(),
                unit_note: None,
                values: sig.u[0].clone(),
            },
        ],
    };
    let m = pendulum_with(&lines("0", "0", "0.001", true));
    let free: Vec<String> = ["d_alpha", "V0_Vm", "Td_Vm"].map(String::from).to_vec();
    let opts = FitOptions {
        free: Some(free),
        ..FitOptions::default()
    };
    let r = fit(&m, &[exp], &opts).expect("fits");
    for (name, want) in [("d_alpha", 0.03), ("V0_Vm", 0.15), ("Td_Vm", 0.0042)] {
        let e = r
            .parameters
            .iter()
            .find(|e| e.name == name)
            .expect("estimate");
        eprintln!(
            "{name}: {:.6e} (true {want:e}), after rmse {:.2e}",
            e.value, r.after_rmse
        );
        assert!((e.value - want).abs() < 1e-8 * want, "{name}: {}", e.value);
    }
}

/// A level on a length coordinate gets the angle template's start and box
/// times `LENGTH_LEVEL_SCALE` (the same decelerations, decay rates and
/// natural frequencies for a cart of up to 10 kg as for a link of up to
/// 0.1 kg m^2); speeds, counts and phases keep theirs. A cogging is in its
/// own form only with half a period within the range its target covers.
#[test]
fn levels_on_a_length_coordinate_are_scaled_and_coggings_need_a_period() {
    use plantc_identify::effect_edit::LENGTH_LEVEL_SCALE;
    let m = model(MASS);
    let k = EffectInstance::candidate(&m, "spring", "x").expect("candidate");
    assert_eq!(k.parameters[0].unit, "N/m");
    assert_eq!(
        k.parameters[0].estimate,
        Some((0.0, LENGTH_LEVEL_SCALE * 1.0))
    );
    assert_eq!(k.parameters[0].value, LENGTH_LEVEL_SCALE * 1e-3);
    let s = EffectInstance::candidate(&m, "stribeck_friction", "x").expect("candidate");
    let vs = s.parameters.iter().find(|p| p.base == "vs").expect("vs");
    assert_eq!((vs.unit.as_str(), vs.estimate), ("m/s", Some((1e-3, 10.0))));
    let fs = s.parameters.iter().find(|p| p.base == "Fs").expect("Fs");
    assert_eq!(fs.estimate, Some((0.0, LENGTH_LEVEL_SCALE * 20.0)));
    let c = EffectInstance::candidate(&m, "cogging", "x").expect("candidate");
    let n = |v: f64| move |name: &str| if name == "N_x" { v } else { 0.5 };
    // a period of 2.9 m over a travel of 0.92 m: a smooth curve, no cogging
    assert!(!c.in_own_form(n(2.16), || 0.0, || 0.92));
    // just under half a period (N = 3 /m over 1 m: 0.48 of one)
    assert!(!c.in_own_form(n(3.0), || 0.0, || 1.0));
    // half a period and more
    assert!(c.in_own_form(n(3.2), || 0.0, || 1.0));
    assert!(c.in_own_form(n(24.0), || 0.0, || 0.4));
}
