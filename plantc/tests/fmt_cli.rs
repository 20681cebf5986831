//! `plantc fmt`: formats in place (only files that change), `--check` for
//! CI, standard input to standard output, and leaves broken files alone.

mod common;

use common::{plantc, repo, s, tmp};
use std::io::Write;
use std::process::{Command, Stdio};

/// A bundled model with its tables no longer aligned (the bundled models
/// are canonical): every run of blanks inside a line squeezed to one.
fn squeezed(m: &str) -> String {
    let text = std::fs::read_to_string(repo().join("models").join(m)).unwrap();
    text.lines()
        .map(|l| {
            let indent = l.len() - l.trim_start().len();
            let rest = l[indent..].split(' ').filter(|w| !w.is_empty());
            format!("{}{}\n", &l[..indent], rest.collect::<Vec<_>>().join(" "))
        })
        .collect()
}

#[test]
fn formats_files_and_directories_in_place() {
    let dir = tmp("fmt");
    let models = ["rotary_pendulum.plant", "cart_pole.plant", "pendubot.plant"];
    for m in models {
        std::fs::write(dir.join(m), squeezed(m)).unwrap();
    }
    std::fs::write(dir.join("notes.txt"), "not a model").unwrap();

    let (code, out, err) = plantc(&["fmt", "--check", &s(&dir)]);
    assert_eq!(code, 1, "{out}{err}");
    // cart_pole's coordinates, aligned on line 6, are its first table
    assert!(
        out.contains("cart_pole.plant: not formatted (first difference on line 6)"),
        "{out}"
    );
    // --check writes nothing
    for m in models {
        assert_eq!(std::fs::read_to_string(dir.join(m)).unwrap(), squeezed(m));
    }

    let (code, out, err) = plantc(&["fmt", &s(&dir)]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(out.matches("formatted ").count(), 3, "{out}");
    for m in models {
        let text = std::fs::read_to_string(dir.join(m)).unwrap();
        // the canonical layout of the squeezed copy is the bundled model
        let want = std::fs::read_to_string(repo().join("models").join(m)).unwrap();
        assert_eq!(text, want, "{m}");
    }
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "not a model"
    );
    // no temporary file is left
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.contains(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");

    // formatted now: --check passes, a second run writes nothing
    let (code, out, _) = plantc(&["fmt", "--check", &s(&dir)]);
    assert_eq!((code, out.as_str()), (0, ""));
    let before = std::fs::metadata(dir.join("pendubot.plant"))
        .unwrap()
        .modified()
        .unwrap();
    let (code, out, _) = plantc(&["fmt", &s(&dir.join("pendubot.plant"))]);
    assert_eq!((code, out.as_str()), (0, ""));
    let after = std::fs::metadata(dir.join("pendubot.plant"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(before, after, "an unchanged file is not rewritten");
}

#[test]
fn a_file_with_syntax_errors_is_left_alone() {
    let dir = tmp("fmt-broken");
    let bad = dir.join("bad.plant");
    let text = "model m\nlet x = (a +\nkinetic  T = 1\n";
    std::fs::write(&bad, text).unwrap();
    let good = dir.join("good.plant");
    std::fs::write(&good, "model   m\n").unwrap();
    let (code, _, err) = plantc(&["fmt", &s(&dir)]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("bad.plant: not formatted: fix the syntax errors first"),
        "{err}"
    );
    assert!(err.contains("error[plantc::syntax]"), "{err}");
    assert_eq!(std::fs::read_to_string(&bad).unwrap(), text);
    // the other files are still formatted
    assert_eq!(std::fs::read_to_string(&good).unwrap(), "model m\n");
    let (code, _, err) = plantc(&["fmt", &s(&dir.join("missing.plant"))]);
    assert_eq!(code, 2);
    assert!(err.contains("no such file"), "{err}");
}

#[test]
fn standard_input_to_standard_output() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args(["fmt", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(b"model  m # the model\nparameter  a=1 [kg]\n")
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        "model m  # the model\nparameter a = 1 [kg]\n"
    );
}

/// Every model file of the repository (tracked by git; the whole tree when
/// git is not at hand) outside `tests/` directories (those keep the layouts
/// their tests are about) is in the canonical layout: `plantc fmt --check`
/// over them passes. Run `plantc fmt FILE` on a file this names.
#[test]
fn every_model_file_of_the_repository_is_canonical() {
    fn walk(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for p in entries {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if p.is_dir() {
                if !(name.starts_with('.') || ["target", "node_modules"].contains(&name)) {
                    walk(&p, out);
                }
            } else if name.ends_with(".plant") {
                out.push(p);
            }
        }
    }
    let tracked = Command::new("git")
        .args(["ls-files", "-z", "--", "*.plant"])
        .current_dir(repo())
        .output()
        .ok()
        .filter(|o| o.status.success() && !o.stdout.is_empty());
    let mut files: Vec<std::path::PathBuf> = match tracked {
        Some(o) => String::from_utf8_lossy(&o.stdout)
            .split('\0')
            .filter(|f| !f.is_empty())
            .map(|f| repo().join(f))
            .collect(),
        None => {
            let mut v = Vec::new();
            walk(&repo(), &mut v);
            v
        }
    };
    files.retain(|f| {
        !f.strip_prefix(repo())
            .unwrap_or(f)
            .components()
            .any(|c| c.as_os_str() == "tests")
    });
    // models/ (10) at least
    assert!(files.len() >= 10, "{files:?}");
    let args: Vec<String> = ["fmt".to_string(), "--check".to_string()]
        .into_iter()
        .chain(files.iter().map(|f| s(f)))
        .collect();
    let (code, out, err) = plantc(&args);
    assert_eq!(
        code, 0,
        "not canonical (run `plantc fmt` on them):\n{out}{err}"
    );
}

/// Issue 31 (r07, r17, FIFO): links back to a directory are not followed (each
/// file once, no endless walk), a FIFO is refused without blocking, a
/// read-only file is not rewritten; each is reported and the other files
/// are still formatted.
#[cfg(unix)]
#[test]
fn links_fifos_and_read_only_files_are_handled_without_hanging() {
    let dir = tmp("fmt_hostile");
    let unformatted = squeezed("cart_pole.plant");
    std::fs::write(dir.join("m.plant"), &unformatted).unwrap();
    std::os::unix::fs::symlink(".", dir.join("a")).unwrap();
    std::os::unix::fs::symlink(".", dir.join("b")).unwrap();
    let (code, out, err) = plantc(&["fmt", "--check", &s(&dir)]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(out.matches("not formatted").count(), 1, "{out}");

    let fifo = dir.join("pipe.plant");
    let st = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(st.success());
    let (code, _, err) = plantc(&["fmt", "--check", &s(&fifo)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file"), "{err}");
    let (code, _, err) = plantc(&["check", &s(&fifo)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file"), "{err}");
    std::fs::remove_file(&fifo).unwrap();

    let ro = dir.join("ro.plant");
    std::fs::write(&ro, &unformatted).unwrap();
    let mut p = std::fs::metadata(&ro).unwrap().permissions();
    p.set_readonly(true);
    std::fs::set_permissions(&ro, p).unwrap();
    let (code, out, err) = plantc(&["fmt", &s(&dir)]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(err.contains("read-only"), "{err}");
    assert_eq!(std::fs::read_to_string(&ro).unwrap(), unformatted);
    assert!(
        out.contains("formatted") && out.contains("m.plant"),
        "{out}"
    );
}
