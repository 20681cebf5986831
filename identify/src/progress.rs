//! What a long identification is doing now, for a progress display: the
//! candidate refits of a diagnosis round ("candidate 4 of 23: spring@theta").
//! The library only records it; the CLI's progress line shows it (on a
//! terminal, not with `--json`).

use std::sync::Mutex;
use std::time::Instant;

/// The latest status and when its round started.
static STATUS: Mutex<Option<(String, Instant)>> = Mutex::new(None);

/// Record that candidates `which` (1-based, in the ranking) of `of` are
/// being refitted, `what` naming the first.
pub fn candidates(which: &[usize], of: usize, what: &str) {
    let list: Vec<String> = which.iter().map(ToString::to_string).collect();
    let which = match list.len() {
        1 => format!("candidate {} of {of}", list[0]),
        _ => format!("candidates {} of {of}", list.join(", ")),
    };
    if let Ok(mut s) = STATUS.lock() {
        let since = s.as_ref().map_or_else(Instant::now, |(_, t)| *t);
        *s = Some((format!("{which} ({what})"), since));
    }
}

/// The round of candidate refits is over.
pub fn clear() {
    if let Ok(mut s) = STATUS.lock() {
        *s = None;
    }
}

/// The present status with the round's elapsed seconds, if a round runs.
pub fn current() -> Option<String> {
    let s = STATUS.lock().ok()?;
    s.as_ref()
        .map(|(what, t)| format!("{what}, {:.1} s", t.elapsed().as_secs_f64()))
}
