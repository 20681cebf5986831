//! Mutants of the reference models through the whole front and middle end
//! (check, load, every parameter set, Euler-Lagrange, linearization, numeric
//! dynamics, every controller, a short simulation): no panic, no stack
//! overflow, no hang (reliability: "5,020 mutated model files").
//!
//! CI runs a bounded number (`PLANTC_MUTANTS`, default 200, deterministic
//! seed `PLANTC_MUTANT_SEED`, default 12). The full run of the issue:
//!
//! ```sh
//! PLANTC_MUTANTS=10000 cargo test --release -p plantc-derive --test model_mutants -- --nocapture
//! ```
//!
//! A panic fails the test naming the mutant; a stack overflow or a mutant
//! taking longer than `PLANTC_MUTANT_SECONDS` (default 60) aborts the
//! process. Either way the mutant is in
//! `target/model-mutants/current.plant` (written before each run).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::control::{resolve, Derivation};
use plantc_derive::lang::{parse_and_check, render, SourceFile};
use plantc_derive::mechanics::NumericDynamics;
use plantc_derive::model::{load_model_text, ParameterValues};
use plantc_derive::simulate::{simulate, Control, ControllerEval, SimOptions, SimProblem};

/// SplitMix64: deterministic mutants for a seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Pieces likely to reach interesting paths, hostile ones included.
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
    "\r",
    "\"",
    "#",
    "1e-3",
    "2+3i",
    "theta",
    "alpha'",
    "sin(",
    "sign(",
    "viscous_friction(",
    "coulomb_friction(",
    "spring(",
    "[kg*m^2]",
    "[m^(1/2)]",
    "let ",
    "force ",
    "set ",
    "controller ",
    "coordinate ",
    "parameter ",
    "\r\n",
    "é",
    "\t",
    "pi",
    "^-1",
    "1e400",
    "/0",
    "0/0",
    "nan",
    "inf",
    "1e-320",
    "^999",
    "\u{200b}",
    "\u{feff}",
    "\0",
    "((((",
    "-(",
    "+",
];

/// Replacement values for number literals.
const NUMBERS: &[&str] = &[
    "0",
    "-1",
    "1e300",
    "1e-300",
    "1e400",
    "0.0",
    "123456789",
    "-0",
    "1e-9",
    "2",
    "-2e5",
];

fn mutate(text: &str, rng: &mut Rng) -> String {
    let mut s: Vec<char> = text.chars().collect();
    for _ in 0..1 + rng.below(3) {
        let n = s.len().max(1);
        match rng.below(11) {
            0 => {
                let at = rng.below(n);
                let end = (at + 1 + rng.below(8)).min(s.len());
                if at < end {
                    s.drain(at..end);
                }
            }
            1 | 2 => {
                let at = rng.below(s.len() + 1);
                let t: Vec<char> = TOKENS[rng.below(TOKENS.len())].chars().collect();
                s.splice(at..at, t);
            }
            3..=6 => {
                // a number literal replaced
                let text: String = s.iter().collect();
                let starts: Vec<usize> =
                    text.char_indices()
                        .filter(|(i, c)| {
                            c.is_ascii_digit()
                                && !text[..*i].chars().last().is_some_and(|p| {
                                    p.is_ascii_alphanumeric() || p == '.' || p == '_'
                                })
                        })
                        .map(|(i, _)| i)
                        .collect();
                if let Some(&b) = starts.get(rng.below(starts.len())) {
                    let len = text[b..]
                        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '-'))
                        .unwrap_or(text.len() - b);
                    let new = format!(
                        "{}{}{}",
                        &text[..b],
                        NUMBERS[rng.below(NUMBERS.len())],
                        &text[b + len..]
                    );
                    s = new.chars().collect();
                }
            }
            7 => {
                // delete, duplicate or swap lines
                let text: String = s.iter().collect();
                let mut lines: Vec<&str> = text.split('\n').collect();
                let (a, b) = (rng.below(lines.len()), rng.below(lines.len()));
                match rng.below(3) {
                    0 => {
                        lines.remove(a);
                    }
                    1 => lines.insert(a, lines[b]),
                    _ => lines.swap(a, b),
                }
                s = lines.join("\n").chars().collect();
            }
            8 | 9 => {
                // a name replaced by another name of the file
                let text: String = s.iter().collect();
                let words: Vec<(usize, &str)> = text
                    .match_indices(|c: char| c.is_ascii_alphabetic())
                    .filter(|(i, _)| *i == 0 || !text.as_bytes()[i - 1].is_ascii_alphanumeric())
                    .map(|(i, _)| {
                        let len = text[i..]
                            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                            .unwrap_or(text.len() - i);
                        (i, &text[i..i + len])
                    })
                    .collect();
                if words.len() > 1 {
                    let (i, w) = words[rng.below(words.len())];
                    let other = words[rng.below(words.len())].1;
                    let new = format!("{}{other}{}", &text[..i], &text[i + w.len()..]);
                    s = new.chars().collect();
                }
            }
            _ => {
                if !s.is_empty() {
                    let (a, b) = (rng.below(s.len()), rng.below(s.len()));
                    s.swap(a, b);
                }
            }
        }
    }
    s.into_iter().collect()
}

/// What happened to a mutant.
#[derive(Default, Debug)]
struct Tally {
    rejected: usize,
    loaded: usize,
    derived: usize,
    simulated: usize,
}

/// The whole pipeline; errors are fine, panics are not.
fn pipeline(text: &str, tally: &mut Tally) {
    let checked = parse_and_check("mutant.plant", text);
    let _ = render(&SourceFile::new("mutant.plant", text), &checked.diagnostics);
    let Ok(loaded) = load_model_text("mutant.plant", text) else {
        tally.rejected += 1;
        return;
    };
    tally.loaded += 1;
    let model = &loaded.model;
    let mut sets: Vec<Option<&str>> = vec![None];
    sets.extend(model.sets.iter().map(|s| Some(s.name.as_str())));
    let values: Vec<ParameterValues> = sets
        .iter()
        .filter_map(|s| ParameterValues::new(model, *s, &[]).ok())
        .collect();
    let Ok(derivation) = Derivation::new(model) else {
        return;
    };
    tally.derived += 1;
    for v in &values {
        let _ = linearize(
            model,
            &derivation.equations,
            v,
            &OperatingPoint::zero(model),
        );
    }
    let Some(v) = values.first() else { return };
    if let Ok(nd) = NumericDynamics::new(model, &derivation.equations) {
        let n = nd.n_states();
        let x: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 + 1.0)).collect();
        let u = vec![0.5; nd.n_inputs()];
        let mut dx = vec![0.0; n];
        let mut ws = nd.workspace();
        if v.full.len() == nd.n_params() {
            let _ = nd.derivatives(&x, &u, &v.full, &mut dx, &mut ws);
        }
    }
    for c in &model.controllers {
        let Ok(ctrl) = resolve(model, &derivation, c.name(), v) else {
            continue;
        };
        let Ok(eval) = ControllerEval::new(model, &ctrl) else {
            continue;
        };
        let mut x0 = vec![0.0; model.state_names().len()];
        if let Some(a) = x0.get_mut(model.coordinates.len().saturating_sub(1)) {
            *a = 0.05;
        }
        let Ok(p) = SimProblem::new(
            model,
            &derivation.equations,
            v,
            Control::Feedback(eval),
            x0,
            0.02,
        ) else {
            continue;
        };
        let opts = SimOptions {
            max_steps: 20_000,
            output_rate: 500.0,
            ..SimOptions::default()
        };
        if simulate(&p, &opts).is_ok() {
            tally.simulated += 1;
        }
    }
}

fn env(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn mutated_models_never_panic_overflow_or_hang() {
    let count = env("PLANTC_MUTANTS", 200) as usize;
    let seed = env("PLANTC_MUTANT_SEED", 12);
    let limit = Duration::from_secs(env("PLANTC_MUTANT_SECONDS", 60));
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut models: Vec<(String, String)> = std::fs::read_dir(root.join("models"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "plant"))
        .map(|p| {
            (
                p.display().to_string(),
                std::fs::read_to_string(&p).unwrap(),
            )
        })
        .collect();
    models.sort();
    assert!(!models.is_empty());
    let dir = root.join("target/model-mutants");
    std::fs::create_dir_all(&dir).unwrap();
    let current = dir.join("current.plant");

    // the watchdog: a mutant running past `limit` aborts the process
    let started = Arc::new(AtomicU64::new(0)); // ms since `t0`, 0 = idle
    let t0 = Instant::now();
    {
        let started = started.clone();
        let current = current.clone();
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_millis(200));
            let s = started.load(Ordering::SeqCst);
            if s > 0 && t0.elapsed().as_millis() as u64 - s > limit.as_millis() as u64 {
                eprintln!(
                    "HANG: a mutant ran longer than {limit:?}; it is in {}",
                    current.display()
                );
                std::process::abort();
            }
        });
    }

    let mut rng = Rng(seed);
    let mut tally = Tally::default();
    let mut slowest = (Duration::ZERO, String::new());
    for k in 0..count {
        let (name, text) = &models[k % models.len()];
        let mutant = mutate(text, &mut rng);
        std::fs::write(&current, &mutant).unwrap();
        started.store(t0.elapsed().as_millis().max(1) as u64, Ordering::SeqCst);
        let t = Instant::now();
        let r = catch_unwind(AssertUnwindSafe(|| pipeline(&mutant, &mut tally)));
        started.store(0, Ordering::SeqCst);
        if t.elapsed() > slowest.0 {
            slowest = (t.elapsed(), format!("mutant {k} of {name}"));
        }
        if r.is_err() {
            let keep = dir.join(format!("panic-{k}.plant"));
            std::fs::write(&keep, &mutant).unwrap();
            panic!("mutant {k} of {name} panicked; it is in {}", keep.display());
        }
    }
    println!(
        "{count} mutants (seed {seed}): {tally:?}; slowest {:.2} s ({})",
        slowest.0.as_secs_f64(),
        slowest.1
    );
    // the mutants reach every stage (not only syntax errors)
    if count >= 60 {
        assert!(tally.derived > count / 10, "{tally:?}");
        assert!(tally.rejected > count / 10, "{tally:?}");
    }
}
