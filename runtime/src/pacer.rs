//! Absolute-deadline periodic timing on the OS monotonic clock.

use std::time::{Duration, Instant};

/// Sleeps until absolute deadlines `start + k * period`, so timing errors do
/// not accumulate. When a deadline was missed by more than a period, the
/// missed instants are skipped (not caught up in a burst) and counted.
#[derive(Debug, Clone)]
pub struct Pacer {
    start: Option<Instant>,
    period: Duration,
    period_s: f64,
    k: u64,
}

impl Pacer {
    /// A pacer with the given period in seconds (must be > 0; otherwise 1 ms).
    pub fn new(period_s: f64) -> Self {
        let period_s = if period_s.is_finite() && period_s > 0.0 {
            period_s
        } else {
            1e-3
        };
        Self {
            start: None,
            period: Duration::from_secs_f64(period_s),
            period_s,
            k: 0,
        }
    }

    /// Waits for the next deadline; returns `(t, missed)` with `t` the nominal
    /// time of the sample since the first call. The first call returns at once with t = 0.
    pub fn wait(&mut self) -> (f64, u32) {
        let Some(start) = self.start else {
            self.start = Some(Instant::now());
            self.k = 0;
            return (0.0, 0);
        };
        self.k += 1;
        let deadline = start + self.period.mul_f64(self.k as f64);
        let now = Instant::now();
        let mut missed = 0u32;
        if now < deadline {
            std::thread::sleep(deadline - now);
        } else {
            let late = (now - deadline).as_secs_f64();
            if late >= self.period_s {
                let skip = (late / self.period_s).floor();
                missed = skip.min(f64::from(u32::MAX)) as u32;
                self.k += u64::from(missed);
                let next = start + self.period.mul_f64(self.k as f64);
                let now = Instant::now();
                if now < next {
                    std::thread::sleep(next - now);
                }
            }
        }
        (self.k as f64 * self.period_s, missed)
    }
}
