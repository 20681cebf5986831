//! Property tests: the front end never panics.

use plantc_derive::lang::{parse_and_check, render, SourceFile};
use proptest::prelude::*;

const FIXTURE: &str = include_str!("fixtures/rotary_pendulum.plant");

fn run(text: &str) {
    let c = parse_and_check("fuzz.plant", text);
    // rendering must not panic either
    let _ = render(&SourceFile::new("fuzz.plant", text), &c.diagnostics);
}

/// Pieces that make mutations likely to hit interesting paths.
const TOKENS: &[&str] = &[
    "(",
    ")",
    "[",
    "]",
    "{",
    "}",
    "'",
    "''",
    "^",
    "*",
    "/",
    "+",
    "-",
    "=",
    ",",
    "\n",
    "\"",
    "#",
    "1e-3",
    "2+3i",
    "theta",
    "alpha'",
    "sin(",
    "viscous_friction(",
    "[kg*m^2]",
    "[m^(1/2)]",
    "let ",
    "force ",
    "set ",
    "controller ",
    "\r\n",
    "é",
    "\t",
    "pi",
    "^-1",
];

#[derive(Debug, Clone)]
enum Mutation {
    Delete(usize, usize),
    Insert(usize, usize),
    Swap(usize, usize),
}

fn apply(text: &str, muts: &[Mutation]) -> String {
    let mut s: Vec<char> = text.chars().collect();
    for m in muts {
        let n = s.len().max(1);
        match *m {
            Mutation::Delete(at, len) => {
                let at = at % n;
                let end = (at + len % 8).min(s.len());
                if at < end {
                    s.drain(at..end);
                }
            }
            Mutation::Insert(at, tok) => {
                let at = (at % (s.len() + 1)).min(s.len());
                let t: Vec<char> = TOKENS[tok % TOKENS.len()].chars().collect();
                s.splice(at..at, t);
            }
            Mutation::Swap(a, b) => {
                if !s.is_empty() {
                    let (a, b) = (a % s.len(), b % s.len());
                    s.swap(a, b);
                }
            }
        }
    }
    s.into_iter().collect()
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Delete(a, b)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Insert(a, b)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Swap(a, b)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_strings_never_panic(s in ".{0,400}") {
        run(&s);
    }

    #[test]
    fn token_soup_never_panics(toks in proptest::collection::vec(0..TOKENS.len(), 0..80)) {
        let s: String = toks.iter().map(|&i| TOKENS[i]).collect();
        run(&s);
    }

    #[test]
    fn mutated_model_never_panics(muts in proptest::collection::vec(mutation(), 1..6)) {
        run(&apply(FIXTURE, &muts));
    }
}

#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    let deep = format!(
        "model m\nlet x = {}1{}\n",
        "(".repeat(5000),
        ")".repeat(5000)
    );
    let c = parse_and_check("deep.plant", &deep);
    assert!(c.has_errors());
    let minus = format!("model m\nlet x = {}1\n", "-".repeat(5000));
    assert!(parse_and_check("deep.plant", &minus).has_errors());
    let pow = format!("model m\nlet x = 2{}\n", "^2".repeat(5000));
    assert!(parse_and_check("deep.plant", &pow).has_errors());
}
