//! `docs/tutorial.md` runs as written: its model file is written (and
//! appended to) where the text says so, and every command of its `sh` blocks
//! runs in order in an empty directory, with the plantc under test for
//! `plantc` (the `cargo install` of step 0 is what the test replaces by the
//! binary it built). The commands are read from the markdown, so the document
//! and the test cannot drift apart.
//!
//! What is checked is robust to changes of the numbers: every command exits
//! 0, writes what the tutorial says it writes, the model is canonical, and
//! the identification names the effect the recordings hide (the tutorial
//! says so).

mod common;

use common::{repo, tmp};
use std::path::Path;
use std::process::Command;

/// One step of the tutorial.
#[derive(Debug)]
enum Step {
    /// `<!-- tutorial: write FILE -->` or `append FILE` before a ```` ```plant ```` block.
    File {
        append: bool,
        name: String,
        text: String,
    },
    /// A command line of a ```` ```sh ```` block (`\` continuations joined).
    Command(String),
}

fn steps(markdown: &str) -> Vec<Step> {
    let lines: Vec<&str> = markdown.lines().collect();
    let mut steps = Vec::new();
    let mut pending: Option<(bool, String)> = None;
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i].trim();
        if let Some(rest) = l
            .strip_prefix("<!-- tutorial:")
            .and_then(|r| r.strip_suffix("-->"))
        {
            let mut w = rest.split_whitespace();
            let op = w.next().expect("tutorial marker: write|append FILE");
            let name = w.next().expect("tutorial marker: a file name");
            assert!(op == "write" || op == "append", "unknown marker {l}");
            pending = Some((op == "append", name.to_string()));
            i += 1;
            continue;
        }
        if let Some(lang) = l.strip_prefix("```") {
            let mut body = Vec::new();
            i += 1;
            while i < lines.len() && lines[i].trim() != "```" {
                body.push(lines[i]);
                i += 1;
            }
            i += 1;
            match lang.trim() {
                "plant" => {
                    if let Some((append, name)) = pending.take() {
                        steps.push(Step::File {
                            append,
                            name,
                            text: body.join("\n") + "\n",
                        });
                    }
                }
                "sh" => {
                    let mut cmd = String::new();
                    for b in body {
                        let b = b.trim();
                        if b.is_empty() || b.starts_with('#') {
                            continue;
                        }
                        match b.strip_suffix('\\') {
                            Some(part) => cmd.push_str(part),
                            None => {
                                cmd.push_str(b);
                                steps.push(Step::Command(std::mem::take(&mut cmd)));
                            }
                        }
                    }
                }
                _ => {}
            }
            continue;
        }
        i += 1;
    }
    steps
}

/// Runs one command line in `dir`: `plantc` is the binary under test,
/// `cargo run` builds offline into the test's own target directory.
fn run(dir: &Path, line: &str) -> (bool, String) {
    let words: Vec<&str> = line.split_whitespace().collect();
    let mut cmd = match words[0] {
        "plantc" => Command::new(env!("CARGO_BIN_EXE_plantc")),
        "cargo" => {
            let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
            c.env("CARGO_TARGET_DIR", dir.join("cargo-target"))
                .env("CARGO_NET_OFFLINE", "true");
            c
        }
        other => panic!("the tutorial runs `{other}`: only plantc and cargo are expected"),
    };
    let out = cmd.args(&words[1..]).current_dir(dir).output().unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn the_tutorial_runs_as_written() {
    let md = std::fs::read_to_string(repo().join("docs/tutorial.md")).unwrap();
    let steps = steps(&md);
    let dir = tmp("tutorial");
    let mut outputs = Vec::new();
    let mut files = 0;
    for step in &steps {
        match step {
            Step::File { append, name, text } => {
                let path = dir.join(name);
                let mut all = if *append {
                    std::fs::read_to_string(&path).expect("appended to a file written before")
                } else {
                    String::new()
                };
                all.push_str(text);
                std::fs::write(&path, all).unwrap();
                files += 1;
            }
            Step::Command(line) if line.starts_with("cargo install") => {
                assert!(line.contains("--locked"), "{line}");
            }
            Step::Command(line) => {
                let (ok, text) = run(&dir, line);
                assert!(ok, "`{line}` failed:\n{text}");
                outputs.push((line.clone(), text));
            }
        }
    }
    // the tutorial's steps: the model in three pieces, then check, derive,
    // linearize, lqr, fmt, sim, synth, identify, gen and the generated example
    assert_eq!(files, 3, "{steps:#?}");
    let ran: Vec<&str> = outputs
        .iter()
        .map(|(l, _)| l.split_whitespace().nth(1).unwrap_or(""))
        .collect();
    for c in [
        "check",
        "derive",
        "linearize",
        "lqr",
        "fmt",
        "sim",
        "synth",
        "identify",
        "gen",
        "run",
    ] {
        assert!(
            ran.contains(&c),
            "the tutorial no longer runs `{c}`: {ran:?}"
        );
    }
    let output_of = |cmd: &str| {
        &outputs
            .iter()
            .find(|(l, _)| l.split_whitespace().nth(1) == Some(cmd))
            .unwrap()
            .1
    };
    // what the text says the commands write
    for f in [
        "lqr.csv",
        "lqr.svg",
        "recordings/driven.csv",
        "recordings/step.csv",
        "recordings/truth.json",
        "identified/fitted.plant",
        "identified/report.json",
        "motor-controller/Cargo.toml",
        "motor-controller/src/lib.rs",
    ] {
        assert!(dir.join(f).is_file(), "{f} was not written");
    }
    // the identification names the hidden dry friction on the load and
    // writes it into the fitted model, which is canonical
    let fitted = std::fs::read_to_string(dir.join("identified/fitted.plant")).unwrap();
    assert!(
        fitted.contains("coulomb_friction("),
        "{}\n{fitted}",
        output_of("identify")
    );
    // every model identify writes (the fitted one, each round's) is canonical
    for e in std::fs::read_dir(dir.join("identified")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "plant") {
            let text = std::fs::read_to_string(&p).unwrap();
            assert_eq!(
                plantc_derive::lang::format::format(&text).unwrap(),
                text,
                "{} is not in the canonical layout",
                p.display()
            );
        }
    }
    // the model the reader wrote is left as it was
    let model = std::fs::read_to_string(dir.join("motor.plant")).unwrap();
    assert!(!model.contains("coulomb_friction"));
    // the generated example ran the closed loop
    assert!(output_of("run").contains("t = "), "{}", output_of("run"));
}
