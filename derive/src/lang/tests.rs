//! Unit tests of the language internals.

use super::ast::{BinOp, ExprKind};
use super::parser::{parse, parse_expr};
use super::units::{parse_unit, Dim, Ratio};
use super::*;
use std::ops::{Div, Mul};

fn show(s: &str) -> String {
    parse_expr(s).unwrap().to_string()
}

#[test]
fn precedence() {
    assert_eq!(show("-x^2"), "(-(x ^ 2))");
    assert_eq!(show("a^b^c"), "(a ^ (b ^ c))");
    assert_eq!(show("a - b - c"), "((a - b) - c)");
    assert_eq!(show("a/b*c"), "((a / b) * c)");
    assert_eq!(show("2^-1"), "(2 ^ (-1))");
    assert_eq!(show("theta''*x'"), "(theta'' * x')");
    assert_eq!(show("1/2*m*x'^2"), "(((1 / 2) * m) * (x' ^ 2))");
}

#[test]
fn continuation_rules() {
    let src = "model m\nkinetic T = a\n    + b\n    - c\nlet x = a +\nb\nlet y = (a\n+ b)\n";
    let (f, d) = parse(src);
    assert!(d.is_empty(), "{d:?}");
    assert_eq!(f.kinetic[0].expr.to_string(), "((a + b) - c)");
    assert_eq!(f.lets[0].expr.to_string(), "(a + b)");
    assert_eq!(f.lets[1].expr.to_string(), "(a + b)");
    // not indented more: a new (bad) statement
    let (_, d) = parse("model m\nkinetic T = a\n+ b\n");
    assert_eq!(d.len(), 1);
}

#[test]
fn literal_text_is_kept() {
    let (f, d) = parse("model m\nparameter J = -9.98E-4 [kg*m^2] estimate [-1e-3, 2.50]\n");
    assert!(d.is_empty());
    let p = &f.parameters[0];
    assert_eq!(p.value.text, "-9.98E-4");
    assert_eq!(p.estimate.as_ref().unwrap().hi.text, "2.50");
    assert_eq!(p.unit.as_ref().unwrap().text, "kg*m^2");
}

#[test]
fn poles() {
    let (f, d) = parse("model m\ncontroller c { place poles [-2+3.464i, -2-3.464i, -40, 5i] }\n");
    assert!(d.is_empty(), "{d:?}");
    let ast::ControllerStmt::Place { poles, .. } = &f.controllers[0].body[0] else {
        panic!()
    };
    let v: Vec<_> = poles.iter().map(|p| p.value()).collect();
    assert_eq!(
        v,
        vec![(-2.0, 3.464), (-2.0, -3.464), (-40.0, 0.0), (0.0, 5.0)]
    );
    assert_eq!(poles[1].im.as_ref().unwrap().text, "-3.464");
}

#[test]
fn units() {
    let u = parse_unit("N*m*s/rad").unwrap();
    assert_eq!(u.dim, Dim::energy().mul(Dim::time()));
    let u = parse_unit("rpm").unwrap();
    assert!((u.scale.to_f64() - 2.0 * std::f64::consts::PI / 60.0).abs() < 1e-15);
    assert_eq!(u.dim, Dim::time().powi(-1));
    assert_eq!(parse_unit("deg").unwrap().scale.to_string(), "1/180*pi");
    assert_eq!(parse_unit("mm").unwrap().scale.ratio, Ratio::new(1, 1000));
    assert_eq!(parse_unit("m/s^2").unwrap().dim.base_form(), "m/s^2");
    assert_eq!(parse_unit("1/s").unwrap().dim.base_form(), "1/s");
    assert_eq!(
        parse_unit("V*s/rad").unwrap().dim,
        parse_unit("N*m/A").unwrap().dim
    );
    assert_eq!(parse_unit("m^(1/2)").unwrap().dim.0[1], Ratio::new(1, 2));
    assert_eq!(parse_unit("").unwrap().dim, Dim::NONE);
    assert!(parse_unit("kg*").is_err());
    assert!(parse_unit("furlong").is_err());
}

#[test]
fn si_values_and_dimensions() {
    let src = "model m\ncoordinate x : length\nparameter l = 300 [mm]\nparameter w = 60 [rpm]\n\
               let v = x'*l\nkinetic T = 1/2*1 [kg]*x'^2\n";
    let c = parse_and_check("t", src);
    assert!(!c.has_errors(), "{:?}", c.diagnostics);
    let s = c.symbols.unwrap();
    assert!((s.parameters["l"].si_value - 0.3).abs() < 1e-15);
    assert!((s.parameters["w"].si_value - 2.0 * std::f64::consts::PI).abs() < 1e-12);
    assert_eq!(s.dim("v"), Some(Dim::length().powi(2).div(Dim::time())));
    let e = parse_expr("sqrt(l*l)/x''").unwrap();
    assert_eq!(dimension_of(&e, &s).unwrap(), Dim::time().powi(2));
    assert!(dimension_of(&parse_expr("l + w").unwrap(), &s).is_err());
}

#[test]
fn effects_expand_with_call_spans() {
    let src = "model m\ncoordinate q : angle\nparameter J = 1 [kg*m^2]\nparameter k = 2 [N*m/rad]\n\
               parameter q0 = 0.1\nparameter Fc = 1 [N*m]\nparameter Fs = 2 [N*m]\nparameter vs = 0.1 [1/s]\n\
               parameter cd = 1 [N*m*s^2]\nkinetic T = 1/2*J*q'^2\n\
               force q = spring(k, q0) + stribeck_friction(Fc, Fs, vs) + quadratic_drag(cd) + spring(k)\n";
    let c = parse_and_check("t", src);
    assert!(!c.has_errors(), "{:?}", c.diagnostics);
    let f = &c.model.unwrap().forces[0];
    let text = f.expr.to_string();
    assert!(text.contains("((-k) * (q - q0))"), "{text}");
    assert!(text.contains("exp((-((q' / vs) ^ 2)))"), "{text}");
    assert!(text.contains("abs(q')"), "{text}");
    // every node of an expansion points into the call
    let call_start = src.find("spring(k, q0)").unwrap();
    let ExprKind::Binary(BinOp::Add, lhs, _) = &f.expr.kind else {
        panic!()
    };
    let mut first = lhs.as_ref();
    while let ExprKind::Binary(BinOp::Add, a, _) = &first.kind {
        first = a;
    }
    assert_eq!(first.span.start, call_start);
    first.walk(&mut |e| assert!(e.span.start >= call_start && e.span.end <= call_start + 13 + 1));
    assert_eq!(f.expr_end, src.trim_end().len());
}

#[test]
fn effect_arity_error() {
    let src = "model m\ncoordinate q : angle\nparameter J = 1 [kg*m^2]\nkinetic T = 1/2*J*q'^2\nforce q = spring()\n";
    let c = parse_and_check("t", src);
    assert!(c.errors().any(|d| d.code == "plantc::wrong_arity"
        && d.help.as_deref().unwrap().contains("spring(k[, q0])")));
}

#[test]
fn miette_diagnostic_impl() {
    let c = parse_and_check("t", "model m\nlet x = y\n");
    let d = c
        .diagnostics
        .iter()
        .find(|d| d.code == "plantc::unknown_name")
        .unwrap();
    let d: &dyn miette::Diagnostic = d;
    assert_eq!(d.code().unwrap().to_string(), "plantc::unknown_name");
    assert_eq!(d.labels().unwrap().count(), 1);
}

/// Quick-fix readings of unknown unit names: one dimension or none.
#[test]
fn unit_readings_keep_the_written_dimension() {
    use super::units::readings;
    // letters that spell known units are read as their product
    assert_eq!(readings("kgm"), vec!["kg*m"]);
    assert_eq!(readings("Nm"), vec!["N*m"]);
    // a case slip
    assert_eq!(readings("hz"), vec!["Hz"]);
    // a typo (kg*g, two masses, is no reading)
    assert_eq!(readings("kgg"), vec!["kg"]);
    // ambiguous: kg*s or a plural kg; N*m*s or N*ms
    assert!(readings("kgs").is_empty());
    assert!(readings("Nms").is_empty());
    // nothing near
    assert!(readings("furlong").is_empty());
    // a long run of letters stays bounded
    assert!(readings(&"m".repeat(60)).len() <= 16);
}
