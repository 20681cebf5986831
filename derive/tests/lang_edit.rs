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

mod rename {
    use plantc_derive::lang::edit::{rename, rename_edits, EditError};
    use plantc_derive::lang::parse_and_check;
    use plantc_derive::lang::visit::SymbolRef;

    fn fixture() -> String {
        super::fixture()
    }

    fn model(n: &str) -> SymbolRef {
        SymbolRef::Model(n.into())
    }

    #[test]
    fn a_let_is_renamed_everywhere_and_nothing_else_changes() {
        let src = fixture();
        let out = rename(&src, &model("J2h"), "J_pend").unwrap();
        assert!(!out.contains("J2h"));
        assert_eq!(out.replace("J_pend", "J2h"), src);
        assert!(!parse_and_check("t", &out).has_errors());
    }

    #[test]
    fn a_parameter_is_renamed_in_sets_and_laws_too() {
        let src = fixture();
        let edits = rename_edits(&src, &model("l2"), "l_2").unwrap();
        // declaration, uses in lets/T/V and the set entry
        let out = rename(&src, &model("l2"), "l_2").unwrap();
        assert_eq!(out.matches("l_2").count(), edits.len());
        assert!(out.contains("    l_2 = 0.1685 [m]") || out.contains("l_2 = 0.1685"));
        assert!(!parse_and_check("t", &out).has_errors());
    }

    /// An `inertia` line is part of the model like a force line: a
    /// parameter used only there is renamed there too (the visitor skipped
    /// these lines, and the rename was refused as breaking the file).
    #[test]
    fn a_parameter_in_an_inertia_line_is_renamed_there_too() {
        let src = fixture()
            + "\nparameter Jr = 1e-4 [kg*m^2] \"rotor\"\ninertia theta = added_inertia(Jr)\n";
        assert!(!parse_and_check("t", &src).has_errors());
        let out = rename(&src, &model("Jr"), "J_rotor").unwrap();
        assert!(
            out.contains("inertia theta = added_inertia(J_rotor)"),
            "{out}"
        );
        assert!(!out.contains("Jr"));
        assert!(!parse_and_check("t", &out).has_errors());
        let out = rename(&src, &model("theta"), "phi").unwrap();
        assert!(out.contains("inertia phi = added_inertia(Jr)"), "{out}");
    }

    #[test]
    fn a_coordinate_is_renamed_with_its_derivatives_forces_and_outputs() {
        let src = fixture();
        let out = rename(&src, &model("alpha"), "phi").unwrap();
        assert!(out.contains("output phi"));
        assert!(out.contains("force phi ="));
        assert!(out.contains("phi'"));
        assert!(out.contains("linearize output phi"));
        assert!(!parse_and_check("t", &out).has_errors());
    }

    #[test]
    fn gains_are_renamed_in_their_controller_only() {
        let src = fixture();
        let Some(ci) = plantc_derive::lang::parser::parse(&src)
            .0
            .controllers
            .iter()
            .position(|c| c.name.name == "feedback_linearization")
        else {
            panic!("fixture has no feedback_linearization controller");
        };
        let before = src.matches("wn").count();
        let out = rename(&src, &SymbolRef::Gain(ci, "wn".into()), "omega").unwrap();
        assert_eq!(
            out.matches("omega").count(),
            3,
            "decl + two uses in its law"
        );
        assert_eq!(out.matches("wn").count(), before - 3);
        assert!(!parse_and_check("t", &out).has_errors());
    }

    #[test]
    fn taken_names_keywords_and_builtins_are_refused() {
        let src = fixture();
        assert_eq!(
            rename(&src, &model("J2h"), "m1"),
            Err(EditError::NameTaken("m1".into()))
        );
        // a parameter may not take the name of a gain that would shadow it in a law
        assert_eq!(
            rename(&src, &model("b1"), "wn"),
            Err(EditError::NameTaken("wn".into()))
        );
        for bad in [
            "sin",
            "pi",
            "parameter",
            "2x",
            "a b",
            "",
            "viscous_friction",
        ] {
            assert!(
                matches!(
                    rename(&src, &model("J2h"), bad),
                    Err(EditError::NotAName(_))
                ),
                "{bad}"
            );
        }
        assert!(matches!(
            rename(&src, &SymbolRef::Builtin("sin".into()), "sine"),
            Err(EditError::NotRenamable(_))
        ));
        let broken = format!("{src}\nlet x = (\n");
        assert!(matches!(
            rename(&broken, &model("J2h"), "J"),
            Err(EditError::InvalidSource(_))
        ));
    }
}
