//! `lang::format`: the canonical layout is idempotent, keeps every comment and
//! leaves the meaning of a model unchanged (same derived equations).

use plantc_derive::lang::format::{comments, format, FormatError};
use plantc_derive::lang::parse_and_check;
use plantc_derive::mechanics::derive_equations;
use plantc_derive::model::load_model_text;
use proptest::prelude::*;
use std::path::PathBuf;

/// Every model of the repository: `models/` and the test fixtures.
fn model_files() -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut v = Vec::new();
    for dir in [root.join("../models"), root.join("tests/fixtures")] {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "plant") {
                v.push(p);
            }
        }
    }
    v.sort();
    assert!(v.len() >= 5, "models not found: {v:?}");
    v
}

/// What `check` says, without positions: codes and messages.
fn diagnostics(text: &str) -> Vec<(String, String)> {
    parse_and_check("m.plant", text)
        .diagnostics
        .iter()
        .map(|d| (d.code.to_string(), d.message.clone()))
        .collect()
}

#[test]
fn models_are_formatted_idempotently_with_the_same_meaning() {
    for path in model_files() {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(&path).unwrap();
        let once = format(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
        let twice = format(&once).unwrap();
        assert_eq!(once, twice, "{name}: not idempotent");
        assert_eq!(comments(&text), comments(&once), "{name}: comments");
        assert_eq!(diagnostics(&text), diagnostics(&once), "{name}: check");
        let a = load_model_text(&name, &text).unwrap().model;
        let b = load_model_text(&name, &once).unwrap().model;
        let (ea, eb) = (derive_equations(&a).unwrap(), derive_equations(&b).unwrap());
        // expressions are hash-consed: equal handles are equal expressions
        assert_eq!(ea.mass_matrix, eb.mass_matrix, "{name}: M(q)");
        assert_eq!(ea.bias, eb.bias, "{name}: bias");
        assert_eq!(ea.forces, eb.forces, "{name}: forces");
        assert_eq!(ea.input_matrix, eb.input_matrix, "{name}: B");
        assert_eq!(a.parameters.len(), b.parameters.len());
        assert_eq!(a.sets.len(), b.sets.len());
        assert_eq!(a.controllers.len(), b.controllers.len());
    }
}

/// A valid file written carelessly (`<TAB>` stands for a tab).
const MESSY: &str = r#"

# a pendulum, written carelessly
model   pendulum "simple pendulum"
coordinate q:angle "angle"   # from upright
coordinate x : length
input u [ N * m ]  limits [ -2 , 2 ]"torque"
output q
parameter m=1[kg] "mass" estimate [0.5,2]



parameter l = 0.5 [m]      "length"
# gravity
parameter g=9.81 [m/s^2]
let I = m*l ^ 2 + 0 [kg*m^2]   # inertia
let c = - m * l  # coupling
kinetic T = 1 / 2 * I * q' ^ 2
<TAB>  + 1/2*m*x'^2
   # a comment inside the expression
          - c*cos( q )*q'*x'
potential V = m*g*l*cos(q)
force q = u+viscous_friction( 0.1 [N*m*s] )-spring(1 [N*m], 0.1)
force x = -m*g*sin(q) * 0 + coulomb_friction(0.2 [N])
set s "other values" { l = 0.6 [m]
  m = 2 [kg] }  # end of set
controller pp { place poles [ -2 + 3i, -2-3i, -4, -5 ] }
controller fl {

linearize output q
 gain wn=4
 v = -wn^2*y
      - 2*wn*y'


}


"#;

fn messy() -> String {
    MESSY.replace("<TAB>", "\t")
}

#[test]
fn a_messy_file_gets_the_canonical_layout() {
    let messy = messy();
    assert!(
        !parse_and_check("m", &messy).has_errors(),
        "{:?}",
        diagnostics(&messy)
    );
    let out = format(&messy).unwrap();
    assert_eq!(format(&out).unwrap(), out);
    assert_eq!(comments(&messy), comments(&out));
    insta::assert_snapshot!(out);
}

#[test]
fn crlf_files_stay_crlf() {
    let text = messy().replace('\n', "\r\n");
    let out = format(&text).unwrap();
    assert_eq!(out, format(&messy()).unwrap().replace('\n', "\r\n"));
}

#[test]
fn files_with_syntax_errors_are_left_alone() {
    let src = "model m\nlet x = (a +\nkinetic T = 1\n";
    match format(src) {
        Err(FormatError::Syntax(d)) => assert!(!d.is_empty()),
        other => panic!("{other:?}"),
    }
}

const MODELS: &[&str] = &[
    include_str!("../../models/rotary_pendulum.plant"),
    include_str!("../../models/pendubot.plant"),
    include_str!("../../models/cart_pole.plant"),
];

/// Pieces inserted by the mutations: comments with awkward contents,
/// whitespace and blank lines.
fn mutation() -> impl Strategy<Value = (usize, u8, String)> {
    let comment = "[ -~αé]{0,12}".prop_map(|s| format!("# {s}"));
    (any::<usize>(), 0u8..5, comment)
}

fn mutate(text: &str, muts: &[(usize, u8, String)]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for (pos, kind, comment) in muts {
        let i = pos % lines.len();
        match kind {
            // a trailing comment (if the line has none yet)
            0 if !lines[i].contains('#') => lines[i] = format!("{}  {comment}", lines[i]),
            // a comment line, indented randomly
            1 => lines.insert(i, format!("{}{comment}", " ".repeat(pos % 7))),
            // a blank line
            2 => lines.insert(i, " ".repeat(pos % 3)),
            // more space after a blank
            3 => {
                if let Some(k) = lines[i].find(' ') {
                    let ws = if pos % 2 == 0 { "  " } else { "\t" };
                    lines[i].insert_str(k, ws);
                }
            }
            // less space: drop one blank around an operator
            _ => lines[i] = lines[i].replacen(" + ", "+", 1).replacen(" = ", "=", 1),
        }
    }
    lines.join("\n") + "\n"
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn formatting_never_loses_a_comment(
        which in 0usize..MODELS.len(),
        muts in prop::collection::vec(mutation(), 1..12),
    ) {
        let text = mutate(MODELS[which], &muts);
        let (_, d) = plantc_derive::lang::parser::parse(&text);
        // a mutation can break the file (e.g. indentation of a continuation):
        // then the formatter must refuse and leave it alone
        match format(&text) {
            Ok(out) => {
                prop_assert!(d.iter().all(|d| !d.is_error()));
                prop_assert_eq!(comments(&text), comments(&out));
                prop_assert_eq!(format(&out).unwrap(), out.clone());
                prop_assert_eq!(diagnostics(&text), diagnostics(&out));
            }
            Err(FormatError::Syntax(_)) => prop_assert!(d.iter().any(|d| d.is_error())),
            Err(e) => prop_assert!(false, "{}", e),
        }
    }
}
