//! A fixed-size log-linear histogram for latency statistics without allocation.

use crate::report::Percentiles;

const SUB_BITS: u32 = 5;
const SUB: usize = 1 << SUB_BITS;
const LINEAR: usize = 2 * SUB;
const BUCKETS: usize = LINEAR + (64 - (SUB_BITS as usize + 1)) * SUB;

/// Histogram of `u64` values (nanoseconds) with exact buckets below 64 and
/// 32 buckets per octave above (about 3 % resolution). All memory is
/// allocated in [`Histogram::new`]; recording never allocates.
#[derive(Debug, Clone)]
pub struct Histogram {
    counts: Vec<u64>,
    n: u64,
    max: u64,
}

fn index(v: u64) -> usize {
    if v < LINEAR as u64 {
        return v as usize;
    }
    let msb = 63 - v.leading_zeros();
    let shift = msb - SUB_BITS;
    let sub = ((v >> shift) as usize) & (SUB - 1);
    LINEAR + (msb as usize - (SUB_BITS as usize + 1)) * SUB + sub
}

fn lower_bound(i: usize) -> u64 {
    if i < LINEAR {
        return i as u64;
    }
    let o = (i - LINEAR) / SUB;
    let sub = (i - LINEAR) % SUB;
    let shift = o as u32 + 1;
    ((SUB + sub) as u64) << shift
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

impl Histogram {
    /// An empty histogram.
    pub fn new() -> Self {
        Self {
            counts: vec![0; BUCKETS],
            n: 0,
            max: 0,
        }
    }

    /// Records one value.
    pub fn record(&mut self, v: u64) {
        if let Some(c) = self.counts.get_mut(index(v)) {
            *c += 1;
        }
        self.n += 1;
        self.max = self.max.max(v);
    }

    /// Number of recorded values.
    pub fn len(&self) -> u64 {
        self.n
    }

    /// True if nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Largest recorded value (exact).
    pub fn max(&self) -> u64 {
        self.max
    }

    /// The `p`-quantile (0..=1), as the lower bound of its bucket, capped at
    /// the maximum; 0 when empty.
    pub fn quantile(&self, p: f64) -> u64 {
        if self.n == 0 {
            return 0;
        }
        let target = ((p.clamp(0.0, 1.0) * self.n as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (i, c) in self.counts.iter().enumerate() {
            acc += c;
            if acc >= target {
                return lower_bound(i).min(self.max);
            }
        }
        self.max
    }

    /// Median, 99th percentile, maximum and count.
    pub fn percentiles(&self) -> Percentiles {
        Percentiles {
            p50: self.quantile(0.5),
            p99: self.quantile(0.99),
            max: self.max(),
            count: self.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_are_monotone_and_tight() {
        let mut last = 0;
        for v in (0..100_000u64).chain([1 << 40, u64::MAX]) {
            let i = index(v);
            assert!(i < BUCKETS);
            assert!(i >= last || v > 100_000);
            last = i;
            let lb = lower_bound(i);
            assert!(lb <= v);
            assert!(v - lb <= v / 30 + 1, "{v} {lb}");
        }
    }

    #[test]
    fn quantiles() {
        let mut h = Histogram::new();
        for v in 1..=1000u64 {
            h.record(v * 1000);
        }
        let p50 = h.quantile(0.5) as f64;
        assert!((p50 - 500_000.0).abs() < 20_000.0, "{p50}");
        assert_eq!(h.max(), 1_000_000);
    }
}
