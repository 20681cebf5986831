//! The rotary pendulum's printed equations, snapshotted next to the thesis'
//! (reference notes `../shared/reference/rotary-pendulum.md`, thesis Eq.
//! 14-15 for the equations of motion, Eq. 26 for the linearizing law):
//! `plantc derive` prints M, bias, Q0, B per equation with the model's own
//! `let` names (J0h, J2h, c), the shorter of sin^2 and 1 - cos^2
//! (`J0h + J2h*sin(alpha)^2` as the model wrote it), `D = det M` named and f
//! over D; `plantc analyze --output alpha` prints the law as its parts
//! `u = (v - L_f^2 h)/(L_g L_f h)`. A reviewer compares the snapshot with
//! the thesis text quoted in each snapshot's description.

mod common;

use common::{model_file, plantc};

const THESIS_EQ_14_15: &str = "thesis Eq. 14-15 (reference notes): \
(J0h + J2h*sin^2 a)*th'' - c*cos(a)*a'' + 2*J2h*sin(a)cos(a)*th'*a' + c*sin(a)*a'^2 = tau - b1*th'; \
-c*cos(a)*th'' + J2h*a'' - J2h*sin(a)cos(a)*th'^2 - m2*g*l2*sin(a) = -b2*a'; \
tau = eta_g*Kg*eta_m*kt*(Vm - Kg*km*th')/Rm";
const THESIS_EQ_26: &str = "thesis Eq. 26: u = (v - L_f^2 h)/(L_g L_f h), h = alpha, \
L_g L_f h proportional to cos(alpha)/D, D = det M";

fn run(args: &[&str]) -> String {
    let (code, out, err) = plantc(args);
    assert_eq!(code, 0, "{err}");
    out
}

#[test]
fn rotary_pendulum_printed_equations_and_law() {
    let m = model_file("rotary_pendulum.plant");
    let derive = run(&["derive", &m]);
    assert!(
        derive.contains("M[0][0] = J0h + J2h*sin(alpha)^2"),
        "{derive}"
    );
    assert!(derive.contains("D = det M"), "{derive}");
    insta::with_settings!({description => THESIS_EQ_14_15, omit_expression => true}, {
        insta::assert_snapshot!("rotary_derive", derive);
    });
    let latex = run(&["derive", &m, "--latex"]);
    insta::with_settings!({description => THESIS_EQ_14_15, omit_expression => true}, {
        insta::assert_snapshot!("rotary_derive_latex", latex);
    });
    let analyze = run(&["analyze", &m, "--output", "alpha", "--set", "thesis"]);
    assert!(
        analyze.contains("linearizing law: u = (v - L_f^2 h)/(L_g L_f h)"),
        "{analyze}"
    );
    insta::with_settings!({description => THESIS_EQ_26, omit_expression => true}, {
        insta::assert_snapshot!("rotary_analyze_alpha", analyze);
    });
}
