//! Valid model files check without errors.

use plantc_derive::lang::{parse_and_check, render, SourceFile};

fn check_fixture(name: &str) -> plantc_derive::lang::Checked {
    let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    let checked = parse_and_check(name, &text);
    if checked.has_errors() {
        panic!(
            "{}",
            render(&SourceFile::new(name, text), &checked.diagnostics)
        );
    }
    checked
}

#[test]
fn rotary_pendulum_checks() {
    let c = check_fixture("rotary_pendulum.plant");
    assert!(c.diagnostics.is_empty(), "{:?}", c.diagnostics);
}
#[test]
fn cart_pole_checks() {
    let c = check_fixture("cart_pole.plant");
    assert!(c.diagnostics.is_empty(), "{:?}", c.diagnostics);
}
