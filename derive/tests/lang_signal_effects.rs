//! `sensor` and `actuator` lines: parsing, printing back, lowering (input
//! offsets folded into the forces) and lossless editing.

use std::collections::HashMap;

use plantc_derive::lang::edit::{add_actuator_effect, add_sensor_effect, EditError};
use plantc_derive::lang::parse_and_check;
use plantc_derive::model::{load_model_text, ActuatorEffectKind, SensorEffectKind};
use plantc_derive::sym::Symbol;

const MODEL: &str = "\
model motor \"a driven arm\"
coordinate theta : angle
coordinate x : length
input Vm [V]
parameter J = 0.01 [kg*m^2]
parameter m = 1 [kg]
parameter k = 0.05 [N*m/V]
parameter d = 0.5 [deg]   # encoder offset
parameter dx = 2 [mm]
parameter V0 = 0.1 [V]
parameter Td = 2 [ms]
kinetic T = 1/2*J*theta'^2 + 1/2*m*x'^2
potential V = 0 [J]
force theta = k*Vm   # motor torque
sensor theta = sensor_offset(d)
sensor x = sensor_offset(dx)
actuator Vm = input_offset(V0)
actuator Vm = input_delay(Td)
actuator Vm = input_delay(2*Td)  # a second delay line adds up
";

fn without_effect_lines() -> String {
    MODEL
        .lines()
        .filter(|l| !l.starts_with("sensor") && !l.starts_with("actuator"))
        .map(|l| format!("{l}\n"))
        .collect()
}

/// Asserts `after` equals `before` with `new` inserted at `at`.
fn assert_inserted(before: &str, after: &str, at: usize, new: &str) {
    assert_eq!(&after[..at], &before[..at], "prefix changed");
    assert_eq!(&after[at..at + new.len()], new, "inserted text");
    assert_eq!(&after[at + new.len()..], &before[at..], "suffix changed");
}

#[test]
fn lines_parse_check_and_print_back() {
    let c = parse_and_check("m.plant", MODEL);
    assert!(!c.has_errors(), "{:?}", c.diagnostics);
    let file = c.model.unwrap();
    assert_eq!(file.sensors.len(), 2);
    assert_eq!(file.actuators.len(), 3);
    assert_eq!(
        file.sensors[0].to_string(),
        "sensor theta = sensor_offset(d)"
    );
    assert_eq!(
        file.actuators[0].to_string(),
        "actuator Vm = input_offset(V0)"
    );
    assert_eq!(
        file.actuators[2].to_string(),
        "actuator Vm = input_delay((2 * Td))"
    );
    // printed lines parse again to the same effect
    for line in file.sensors.iter().chain(file.actuators.iter()) {
        let text = without_effect_lines() + &line.to_string() + "\n";
        let c = parse_and_check("m.plant", &text);
        assert!(!c.has_errors(), "{text}: {:?}", c.diagnostics);
    }
}

#[test]
fn lowering_lists_effects_and_folds_the_input_offset() {
    let m = load_model_text("m.plant", MODEL).unwrap().model;
    assert_eq!(m.sensors.len(), 2);
    assert_eq!(m.sensors[0].coordinate, 0);
    assert_eq!(m.sensors[1].coordinate, 1);
    assert!(matches!(m.sensors[0].effect, SensorEffectKind::Offset(_)));
    assert_eq!(m.actuators.len(), 3);
    assert!(matches!(
        m.actuators[0].effect,
        ActuatorEffectKind::Offset(_)
    ));
    assert!(matches!(
        m.actuators[1].effect,
        ActuatorEffectKind::Delay(_)
    ));
    let values: HashMap<Symbol, f64> = m
        .parameters
        .iter()
        .map(|p| (p.symbol, p.value))
        .chain([(Symbol::new("Vm"), 3.0)])
        .collect();
    // SI values: d = 0.5 deg, dx = 2 mm, total delay Td + 2 Td = 6 ms
    let d = m.sensor_offset(0).eval_map(&values);
    assert!((d - 0.5_f64.to_radians()).abs() < 1e-15, "{d}");
    assert!((m.sensor_offset(1).eval_map(&values) - 2e-3).abs() < 1e-15);
    assert!((m.input_delay(0).eval_map(&values) - 6e-3).abs() < 1e-15);
    // force on theta = k*(Vm + V0) = 0.05*(3 + 0.1)
    let f = m.forces[0].eval_map(&values);
    assert!((f - 0.05 * 3.1).abs() < 1e-15, "{f}");
    assert!(m.forces[0].contains(Symbol::new("V0")));
    let ignored = m.ignored_signal_effects();
    assert_eq!(ignored.len(), 4, "{ignored:?}");
    assert!(ignored[0].starts_with("sensor theta = sensor_offset("));
}

#[test]
fn two_offsets_on_one_input_compose() {
    let text = without_effect_lines()
        + "parameter V1 = 0.2 [V]\nactuator Vm = input_offset(V0)\nactuator Vm = input_offset(V1)\n";
    let m = load_model_text("m.plant", &text).unwrap().model;
    let values: HashMap<Symbol, f64> = m
        .parameters
        .iter()
        .map(|p| (p.symbol, p.value))
        .chain([(Symbol::new("Vm"), 1.0)])
        .collect();
    let f = m.forces[0].eval_map(&values);
    assert!((f - 0.05 * 1.3).abs() < 1e-15, "{f}");
}

#[test]
fn add_sensor_effect_appends_a_line_after_the_last_effect_line() {
    let src = without_effect_lines();
    let out = add_sensor_effect(&src, "theta", "sensor_offset(d)").unwrap();
    let at = src.find("force theta").unwrap() + "force theta = k*Vm   # motor torque\n".len();
    assert_inserted(&src, &out, at, "sensor theta = sensor_offset(d)\n");
    // the next one goes after the sensor line
    let out2 = add_actuator_effect(&out, "Vm", "input_delay(Td)").unwrap();
    let at2 = at + "sensor theta = sensor_offset(d)\n".len();
    assert_inserted(&out, &out2, at2, "actuator Vm = input_delay(Td)\n");
    assert!(!parse_and_check("m", &out2).has_errors());
}

#[test]
fn add_actuator_effect_keeps_crlf_and_comments() {
    let src = without_effect_lines().replace('\n', "\r\n");
    let out = add_actuator_effect(&src, "Vm", "  input_offset(V0) ").unwrap();
    let at = src.find("force theta").unwrap() + "force theta = k*Vm   # motor torque\r\n".len();
    assert_inserted(&src, &out, at, "actuator Vm = input_offset(V0)\r\n");
    assert!(!out.replace("\r\n", "").contains('\n'));
}

#[test]
fn add_effect_without_trailing_newline() {
    let src = without_effect_lines();
    let src = src.trim_end();
    let out = add_sensor_effect(src, "x", "sensor_offset(dx)").unwrap();
    assert_inserted(src, &out, src.len(), "\nsensor x = sensor_offset(dx)");
}

#[test]
fn add_effect_refuses_bad_input() {
    let src = without_effect_lines();
    match add_sensor_effect(&src, "thta", "sensor_offset(d)") {
        Err(EditError::UnknownCoordinate { suggestions, .. }) => {
            assert_eq!(suggestions, ["theta"])
        }
        other => panic!("{other:?}"),
    }
    match add_actuator_effect(&src, "Vn", "input_delay(Td)") {
        Err(EditError::UnknownInput { suggestions, .. }) => assert_eq!(suggestions, ["Vm"]),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        add_sensor_effect(&src, "theta", "d"),
        Err(EditError::NotAnEffectCall(_))
    ));
    assert!(matches!(
        add_sensor_effect(&src, "theta", "sensor_offset(d)\nforce x = 0"),
        Err(EditError::NotAnEffectCall(_))
    ));
    // wrong kind and wrong unit are refused by the re-check
    assert!(matches!(
        add_sensor_effect(&src, "theta", "input_offset(V0)"),
        Err(EditError::WouldBreak(_))
    ));
    assert!(matches!(
        add_actuator_effect(&src, "Vm", "input_delay(V0)"),
        Err(EditError::WouldBreak(_))
    ));
    assert!(matches!(
        add_sensor_effect(&src, "x", "sensor_offset(d)"),
        Err(EditError::WouldBreak(_))
    ));
}

#[test]
fn consumers_of_the_plant_equations_get_warnings() {
    let loaded = load_model_text("m.plant", MODEL).unwrap();
    let w = loaded.ignored_signal_effects("`plantc sim`");
    // two sensor offsets and two delays; the input offset is folded, no warning
    assert_eq!(w.len(), 4);
    assert!(w.iter().all(|d| !d.is_error()));
    let lines: Vec<&str> = w
        .iter()
        .map(|d| &MODEL[d.primary.start..d.primary.end])
        .collect();
    assert_eq!(
        lines,
        [
            "sensor theta = sensor_offset(d)",
            "sensor x = sensor_offset(dx)",
            "actuator Vm = input_delay(Td)",
            "actuator Vm = input_delay(2*Td)"
        ]
    );
    let plain = load_model_text("m.plant", &without_effect_lines()).unwrap();
    assert!(plain.ignored_signal_effects("`plantc sim`").is_empty());
}

/// `deadzone(w)` stays out of the forces (they must stay linear in the
/// inputs), is listed in `Model::actuators`, widths of several lines add and
/// plant-equation consumers are warned about it.
#[test]
fn deadzone_is_lowered_unfolded_and_widths_add() {
    let text = without_effect_lines()
        + "parameter w = 0.3 [V]\nactuator Vm = input_offset(V0)\n\
           actuator Vm = deadzone(w)\nactuator Vm = deadzone(w/3)  # widths add\n";
    let loaded = load_model_text("m.plant", &text).unwrap();
    let m = &loaded.model;
    assert_eq!(m.actuators.len(), 3);
    assert!(matches!(
        m.actuators[1].effect,
        ActuatorEffectKind::Deadzone(_)
    ));
    assert!(m.has_deadzone());
    let values: HashMap<Symbol, f64> = m
        .parameters
        .iter()
        .map(|p| (p.symbol, p.value))
        .chain([(Symbol::new("Vm"), 3.0)])
        .collect();
    // 0.3 V + 0.1 V
    let w = m.input_deadzone(0).eval_map(&values);
    assert!((w - 0.4).abs() < 1e-15, "{w}");
    assert_eq!(m.input_delay(0).eval_map(&values), 0.0);
    // the force holds only the folded offset: k*(Vm + V0), no `w`
    let f = m.forces[0].eval_map(&values);
    assert!((f - 0.05 * 3.1).abs() < 1e-15, "{f}");
    assert!(!m.forces[0].contains(Symbol::new("w")));
    assert_eq!(
        m.ignored_signal_effects(),
        ["actuator Vm = deadzone(w)", "actuator Vm = deadzone(w/3)"]
            .map(String::from)
            .to_vec()
    );
    let warned: Vec<&str> = loaded
        .ignored_signal_effects("`plantc sim`")
        .iter()
        .map(|d| &text[d.primary.start..d.primary.end])
        .collect();
    assert_eq!(
        warned,
        ["actuator Vm = deadzone(w)", "actuator Vm = deadzone(w/3)"]
    );
    // printing back parses to the same line
    let file = parse_and_check("m.plant", &text).model.unwrap();
    assert_eq!(file.actuators[1].to_string(), "actuator Vm = deadzone(w)");
    // a model without deadzone has none
    let plain = load_model_text("m.plant", &without_effect_lines()).unwrap();
    assert!(!plain.model.has_deadzone());
    assert_eq!(plain.model.input_deadzone(0).eval_map(&values), 0.0);
}

/// A zero width is valid (the effect then does nothing); a deadzone on a
/// coordinate or with the wrong unit is refused by the edit re-check.
#[test]
fn deadzone_zero_width_is_valid_and_bad_lines_are_refused() {
    let src = without_effect_lines() + "parameter w = 0 [V]\n";
    let out = add_actuator_effect(&src, "Vm", "deadzone(w)").unwrap();
    assert!(out.contains("\nactuator Vm = deadzone(w)\n"), "{out}");
    assert!(!parse_and_check("m.plant", &out).has_errors());
    assert!(matches!(
        add_actuator_effect(&src, "Vm", "deadzone(Td)"),
        Err(EditError::WouldBreak(_))
    ));
    assert!(matches!(
        add_sensor_effect(&src, "theta", "deadzone(w)"),
        Err(EditError::WouldBreak(_))
    ));
}
