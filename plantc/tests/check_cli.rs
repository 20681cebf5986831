//! `plantc check --json`: one JSON object on standard output whatever the
//! outcome, with every diagnostic (errors, warnings, notes) and its location.

mod common;

use common::{model, plantc, s, tmp};

fn check_json(path: &str) -> (i32, serde_json::Value, String) {
    let (code, out, err) = plantc(&["check", "--json", path]);
    let v: serde_json::Value = serde_json::from_str(&out)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {out:?}\nstderr: {err}"));
    (code, v, err)
}

#[test]
fn errors_are_printed_as_json_with_their_locations() {
    let dir = tmp("check-json");
    let f = dir.join("bad.plant");
    // line 4: an unknown unit (error); line 5: an unknown name (error)
    std::fs::write(
        &f,
        "model m\ncoordinate q : angle\ninput u [N*m]\nparameter J = 1 [kgm^2]\nkinetic T = 1/2*J*q'^2 + zz\nforce q = u\n",
    )
    .unwrap();
    let (code, v, err) = check_json(&s(&f));
    assert_eq!(code, 2, "{v}");
    assert_eq!(v["ok"], false);
    assert_eq!(v["file"], s(&f));
    let d = v["diagnostics"].as_array().unwrap();
    assert_eq!(
        v["errors"],
        d.iter().filter(|x| x["severity"] == "error").count()
    );
    let unit = d
        .iter()
        .find(|x| x["code"] == "plantc::unknown_unit")
        .expect("the unit error");
    assert_eq!(unit["severity"], "error");
    assert_eq!(unit["message"], "unknown unit `kgm`");
    // `kgm` starts in column 18 of line 4 (1-based, characters)
    assert_eq!(
        (unit["line"].as_u64(), unit["column"].as_u64()),
        (Some(4), Some(18))
    );
    assert_eq!(unit["end_column"], 21);
    assert!(unit["help"].is_string());
    let name = d
        .iter()
        .find(|x| x["code"] == "plantc::unknown_name")
        .expect("the name error");
    assert_eq!(name["line"], 5);
    // the rendered diagnostics still go to standard error
    assert!(err.contains("unknown unit `kgm`"), "{err}");
}

#[test]
fn a_valid_model_lists_its_warnings_and_names() {
    let (code, v, _) = check_json(&model());
    assert_eq!(code, 0, "{v}");
    assert_eq!(v["ok"], true);
    assert_eq!(v["model"], "rotary_pendulum");
    assert_eq!(v["errors"], 0);
    assert!(v["diagnostics"].is_array());
    assert_eq!(v["coordinates"], serde_json::json!(["theta", "alpha"]));

    // a warning is in the list with its severity
    let dir = tmp("check-json-warning");
    let f = dir.join("w.plant");
    std::fs::write(
        &f,
        "model m\ncoordinate q : angle\ninput u [N*m]\nparameter J = -1 [kg*m^2]\nkinetic T = 1/2*J*q'^2\nforce q = u\n",
    )
    .unwrap();
    let (code, v, _) = check_json(&s(&f));
    assert_eq!(code, 0, "{v}");
    let d = v["diagnostics"].as_array().unwrap();
    assert!(
        d.iter()
            .any(|x| x["severity"] == "warning" && x["line"] == 4),
        "{v}"
    );
    assert_eq!(
        v["warnings"],
        d.iter().filter(|x| x["severity"] == "warning").count()
    );
}

#[test]
fn an_unreadable_file_is_a_json_error_too() {
    let (code, v, _) = check_json("does/not/exist.plant");
    assert_eq!(code, 2);
    assert_eq!(v["ok"], false);
    assert_eq!(v["diagnostics"][0]["severity"], "error");
    assert_eq!(v["diagnostics"][0]["code"], "plantc::io");
}
