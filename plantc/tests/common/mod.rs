//! Helpers shared by the `plantc` integration tests (`mod common;` in each
//! test file). Not every test file uses every helper.
#![allow(dead_code)]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The workspace root (the parent of the `plantc` crate).
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the plantc crate sits in the workspace")
        .to_path_buf()
}

/// Path of `models/<name>` as a string argument.
pub fn model_file(name: &str) -> String {
    s(&repo().join("models").join(name))
}

/// Path of `models/rotary_pendulum.plant`.
pub fn model_path() -> PathBuf {
    repo().join("models/rotary_pendulum.plant")
}

/// Path of `models/rotary_pendulum.plant` as a string argument.
pub fn model() -> String {
    s(&model_path())
}

/// A fresh (emptied) temporary directory, unique to this test binary
/// (`plantc-<test file>-<pid>-<name>`).
pub fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "plantc-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> String {
    p.display().to_string()
}

/// Runs `plantc <args>` in this process through `plantc::run`:
/// (exit code, stdout, stderr).
pub fn plantc<A: AsRef<OsStr>>(args: &[A]) -> (i32, String, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let mut all = vec![OsStr::new("plantc")];
    all.extend(args.iter().map(AsRef::as_ref));
    let code = plantc::run(all, &mut out, &mut err);
    (
        code,
        String::from_utf8(out).expect("utf-8 stdout"),
        String::from_utf8(err).expect("utf-8 stderr"),
    )
}

/// Runs the built `plantc` binary with `args` in the workspace root, as a
/// separate process: (exit code or -1, stdout, stderr).
pub fn plantc_bin<A: AsRef<OsStr>>(args: &[A]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The number after `key` in `text` (e.g. `max |Vm difference| `).
pub fn number_after(text: &str, key: &str) -> Option<f64> {
    let rest = &text[text.find(key)? + key.len()..];
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || "+-.e".contains(c)))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// Builds (once per test binary) and locates the fake HIL cdylib
/// (`runtime/fake-hil`), as the runtime's own tests do.
pub fn fake_hil_lib() -> PathBuf {
    use std::sync::OnceLock;
    static PATH: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    PATH.get_or_init(|| {
        let status = Command::new(env!("CARGO"))
            .args(["build", "-p", "plantc-fake-hil"])
            .current_dir(repo())
            .status()
            .map_err(|e| format!("running cargo: {e}"))?;
        if !status.success() {
            return Err(format!("cargo build -p plantc-fake-hil: {status}"));
        }
        let name = format!(
            "{}plantc_fake_hil{}",
            std::env::consts::DLL_PREFIX,
            std::env::consts::DLL_SUFFIX
        );
        let mut candidates = Vec::new();
        if let Ok(exe) = std::env::current_exe() {
            // target/<profile>/deps/<test> -> target/debug/ (what the
            // build above made), then target/<profile>/ (a release test run
            // would otherwise load a stale library left there)
            if let Some(dir) = exe.parent().and_then(|d| d.parent()) {
                if let Some(target) = dir.parent() {
                    candidates.push(target.join("debug").join(&name));
                }
                candidates.push(dir.join(&name));
            }
        }
        if let Ok(t) = std::env::var("CARGO_TARGET_DIR") {
            candidates.push(PathBuf::from(t).join("debug").join(&name));
        }
        candidates.push(repo().join("target/debug").join(&name));
        candidates
            .iter()
            .find(|p| p.is_file())
            .cloned()
            .ok_or_else(|| format!("{name} not found in {candidates:?}"))
    })
    .clone()
    .unwrap_or_else(|e| panic!("cannot build/locate the fake HIL: {e}"))
}
