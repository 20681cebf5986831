//! kill -9 during a real-time run: the log still parses and lacks at most
//! 100 ms of samples.

mod common;

use common::{parse_log, tmp_path};
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

fn example_binary() -> PathBuf {
    let workspace = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf();
    let status = Command::new(env!("CARGO"))
        .args(["build", "-p", "plantc-runtime", "--example", "sim_realtime"])
        .current_dir(&workspace)
        .status()
        .expect("cargo");
    assert!(status.success());
    let name = format!("sim_realtime{}", std::env::consts::EXE_SUFFIX);
    let exe = std::env::current_exe().unwrap();
    let mut candidates = Vec::new();
    if let Some(target) = exe
        .parent()
        .and_then(|d| d.parent())
        .and_then(|d| d.parent())
    {
        candidates.push(target.join("debug").join("examples").join(&name));
    }
    if let Ok(t) = std::env::var("CARGO_TARGET_DIR") {
        candidates.push(PathBuf::from(t).join("debug").join("examples").join(&name));
    }
    candidates.push(workspace.join("target/debug/examples").join(&name));
    candidates
        .into_iter()
        .find(|p| p.is_file())
        .expect("example binary")
}

/// The last complete row's t in the file, if any.
fn last_t(text: &str) -> Option<f64> {
    let complete = &text[..text.rfind('\n')? + 1];
    let last = complete.lines().last()?;
    last.split(',').next()?.parse().ok()
}

#[test]
fn kill_9_leaves_a_parsable_log_missing_at_most_100_ms() {
    let exe = example_binary();
    let path = tmp_path("kill.csv");
    let _ = std::fs::remove_file(&path);
    let mut child = Command::new(&exe)
        .arg(&path)
        .arg("30")
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("spawn");
    // Watch the file grow. Rows appear only after they were executed, so
    // every observation bounds the loop's start: start <= seen_at - t_last.
    let mut start_bound = f64::INFINITY;
    let t0 = Instant::now();
    let mut last_len = 0;
    loop {
        let now = t0.elapsed().as_secs_f64();
        if let Ok(text) = std::fs::read_to_string(&path) {
            if text.len() != last_len {
                last_len = text.len();
                if let Some(t) = last_t(&text) {
                    start_bound = start_bound.min(now - t);
                }
            }
        }
        if start_bound.is_finite() && now - start_bound > 1.5 {
            break;
        }
        assert!(now < 20.0, "log did not grow");
        std::thread::sleep(Duration::from_micros(500));
    }
    let kill_at = t0.elapsed().as_secs_f64();
    child.kill().expect("kill -9");
    let _ = child.wait();
    let t_kill = kill_at - start_bound;

    let text = std::fs::read_to_string(&path).expect("log");
    let rows = parse_log(&text, true).expect("log parses after kill -9");
    let t_last = rows.last().expect("rows").t;
    let missing = t_kill - t_last;
    println!(
        "kill at loop time ~{t_kill:.4} s, last logged t {t_last:.4} s, missing {:.1} ms ({} rows)",
        missing * 1e3,
        rows.len()
    );
    // 100 ms flush interval, plus up to ~5 ms for observing the file by polling.
    assert!(missing <= 0.105, "missing {:.1} ms", missing * 1e3);
    // Consecutive samples, none lost in the middle of the file.
    for w in rows.windows(2) {
        assert!(
            w[1].t - w[0].t < 0.0015 || w[1].overrun,
            "{} -> {}",
            w[0].t,
            w[1].t
        );
    }
}
