//! Lossless editing: only the edited bytes change.

use plantc_derive::lang::edit::{
    add_force_term, add_parameter, number_text, set_estimate, set_parameter_value, EditError,
};
use plantc_derive::lang::parse_and_check;

fn fixture() -> String {
    std::fs::read_to_string(format!(
        "{}/tests/fixtures/rotary_pendulum.plant",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

/// Asserts `after` equals `before` with `before[start..end]` replaced by `new`.
fn assert_only_changed(before: &str, after: &str, start: usize, end: usize, new: &str) {
    assert_eq!(&after[..start], &before[..start], "prefix changed");
    assert_eq!(&after[start..start + new.len()], new, "edited span");
    assert_eq!(
        &after[start + new.len()..],
        &before[end..],
        "suffix changed"
    );
}

fn valid(text: &str) {
    let c = parse_and_check("t.plant", text);
    assert!(!c.has_errors(), "{:?}", c.diagnostics);
}

#[test]
fn set_value_replaces_only_the_literal() {
    let src = fixture();
    let out = set_parameter_value(&src, "l2", "0.1656").unwrap();
    let start = src.find("0.156     [m]").unwrap();
    assert_only_changed(&src, &out, start, start + "0.156".len(), "0.1656");
    valid(&out);
    let c = parse_and_check("t", &out);
    let v = c.symbols.unwrap().parameters["l2"].si_value;
    assert!((v - 0.1656).abs() < 1e-15);
}

#[test]
fn set_value_keeps_crlf_and_comments() {
    let src = fixture().replace('\n', "\r\n");
    let out = set_parameter_value(&src, "b2", "8.5e-4").unwrap();
    let start = src.find("0.0024    [N*m*s/rad] \"pendulum").unwrap();
    assert_only_changed(&src, &out, start, start + "0.0024".len(), "8.5e-4");
    assert_eq!(out.matches("\r\n").count(), src.matches("\r\n").count());
    valid(&out);
}

#[test]
fn set_value_rejects_bad_input() {
    let src = fixture();
    assert!(matches!(
        set_parameter_value(&src, "l2", "1+2"),
        Err(EditError::NotANumber(_))
    ));
    match set_parameter_value(&src, "l3", "1") {
        Err(EditError::UnknownParameter { suggestions, .. }) => {
            assert!(suggestions.contains(&"l2".to_string()))
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        set_parameter_value("model m\nlet = 3\n", "x", "1"),
        Err(EditError::InvalidSource(_))
    ));
}

#[test]
fn negative_value() {
    let src = fixture();
    let out = set_parameter_value(&src, "g", "-9.81").unwrap();
    valid(&out);
    assert!(out.contains("parameter g  = -9.81      [m/s^2]"));
}

#[test]
fn set_estimate_replaces_existing_bounds() {
    let src = fixture();
    let out = set_estimate(&src, "b1", "1e-4", "0.05").unwrap();
    let start = src.find("estimate [0, 0.02]").unwrap() + "estimate [".len();
    assert_only_changed(&src, &out, start, start + "0, 0.02".len(), "1e-4, 0.05");
    valid(&out);
}

#[test]
fn set_estimate_adds_bounds() {
    let src = fixture();
    let out = set_estimate(&src, "J2", "5e-4", "3e-3").unwrap();
    let at = src
        .find("\"pendulum inertia about its centre of mass\"")
        .unwrap()
        + "\"pendulum inertia about its centre of mass\"".len();
    assert_only_changed(&src, &out, at, at, " estimate [5e-4, 3e-3]");
    valid(&out);
}

#[test]
fn set_estimate_refuses_reversed_bounds() {
    let src = fixture();
    assert!(matches!(
        set_estimate(&src, "J2", "3e-3", "5e-4"),
        Err(EditError::WouldBreak(_))
    ));
}

#[test]
fn add_term_to_existing_force() {
    let src = fixture();
    let src = add_parameter(
        &src,
        "parameter Fc_alpha = 0.001 [N*m] \"pendulum dry friction\" estimate [0, 0.01]",
    )
    .unwrap();
    let out = add_force_term(&src, "alpha", "+ coulomb_friction(Fc_alpha)").unwrap();
    let line = "force alpha = viscous_friction(b2)";
    let at = src.find(line).unwrap() + line.len();
    assert_only_changed(&src, &out, at, at, " + coulomb_friction(Fc_alpha)");
    valid(&out);
    // the expanded force mentions sign(alpha')
    let c = parse_and_check("t", &out);
    let f = &c.model.unwrap().forces[1];
    assert!(f.expr.to_string().contains("sign(alpha')"), "{}", f.expr);
}

#[test]
fn add_term_without_sign_and_before_comment() {
    let src = "model m\ncoordinate x : length\nparameter M = 1 [kg]\nparameter k = 2 [N/m]\nkinetic T = 1/2*M*x'^2\nforce x = spring(k)   # restoring\n";
    let out = add_force_term(src, "x", "spring(k, 1 [m])").unwrap();
    assert_eq!(
        out,
        "model m\ncoordinate x : length\nparameter M = 1 [kg]\nparameter k = 2 [N/m]\nkinetic T = 1/2*M*x'^2\nforce x = spring(k) + spring(k, 1 [m])   # restoring\n"
    );
}

#[test]
fn add_term_creates_force_line() {
    let src = fixture();
    let without = src.replace("force alpha = viscous_friction(b2)\n", "");
    let out = add_force_term(&without, "alpha", "+ viscous_friction(b2)").unwrap();
    assert_eq!(out, src);
}

#[test]
fn add_term_creates_first_force_line_crlf() {
    let src = "model m\r\ncoordinate x : length\r\nparameter M = 1 [kg]\r\nparameter b = 2 [N*s/m]\r\nkinetic T = 1/2*M*x'^2\r\n# end\r\n";
    let out = add_force_term(src, "x", "viscous_friction(b)").unwrap();
    assert_eq!(
        out,
        "model m\r\ncoordinate x : length\r\nparameter M = 1 [kg]\r\nparameter b = 2 [N*s/m]\r\nkinetic T = 1/2*M*x'^2\r\nforce x = viscous_friction(b)\r\n# end\r\n"
    );
}

#[test]
fn add_term_refuses_wrong_unit_and_unknown_coordinate() {
    let src = fixture();
    // b2 is a viscous coefficient, not a Coulomb level
    assert!(matches!(
        add_force_term(&src, "alpha", "+ coulomb_friction(b2)"),
        Err(EditError::WouldBreak(_))
    ));
    assert!(matches!(
        add_force_term(&src, "alpa", "+ viscous_friction(b2)"),
        Err(EditError::UnknownCoordinate { .. })
    ));
}

#[test]
fn add_parameter_after_last_parameter() {
    let src = fixture();
    let decl = "parameter Fc2 = 0.001 [N*m] \"pendulum dry friction\"";
    let out = add_parameter(&src, decl).unwrap();
    let last = "parameter Fg1 = 0.01 [N*m] \"gearbox dry friction\" estimate [0, 0.1]\n";
    let at = src.find(last).unwrap() + last.len();
    assert_only_changed(&src, &out, at, at, &format!("{decl}\n"));
    valid(&out);
    assert!(matches!(
        add_parameter(&src, "let x = 1"),
        Err(EditError::NotAParameterDeclaration(_))
    ));
    assert!(matches!(
        add_parameter(&src, "parameter m1 = 1 [kg]"),
        Err(EditError::WouldBreak(_))
    ));
}

#[test]
fn number_text_round_trips() {
    for v in [0.0024, 1e-7, 123456789.0, -0.5, 0.0] {
        let t = number_text(v);
        assert_eq!(t.parse::<f64>().unwrap(), v);
        let src = fixture();
        valid(&set_parameter_value(&src, "b1", &t).unwrap_or_else(|e| panic!("{t}: {e}")));
    }
}
