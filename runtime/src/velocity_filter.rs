//! Filtered derivative for velocity estimation from encoder angles.

/// The high-pass derivative `H(s) = wc s / (s + wc)` discretised by Tustin,
/// as in Quanser's examples (wc = 50 rad/s by default):
///
/// `y[k] = ((2 - wc T) y[k-1] + 2 wc (q[k] - q[k-1])) / (2 + wc T)`.
///
/// The first sample initialises the filter (zero velocity, no start-up spike).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityFilter {
    a: f64,
    b: f64,
    prev_q: f64,
    y: f64,
    primed: bool,
}

impl VelocityFilter {
    /// A filter with bandwidth `wc` (rad/s) for sample period `period` (s).
    pub fn new(wc: f64, period: f64) -> Self {
        let den = 2.0 + wc * period;
        Self {
            a: (2.0 - wc * period) / den,
            b: 2.0 * wc / den,
            prev_q: 0.0,
            y: 0.0,
            primed: false,
        }
    }

    /// Feeds the angle `q` of the current sample and returns the velocity estimate.
    pub fn update(&mut self, q: f64) -> f64 {
        if !self.primed {
            self.primed = true;
            self.prev_q = q;
            self.y = 0.0;
            return 0.0;
        }
        self.y = self.a * self.y + self.b * (q - self.prev_q);
        self.prev_q = q;
        self.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_converges_to_slope() {
        let mut f = VelocityFilter::new(50.0, 1e-3);
        let mut v = 0.0;
        for k in 0..2000 {
            v = f.update(3.0 * k as f64 * 1e-3);
        }
        assert!((v - 3.0).abs() < 1e-9, "{v}");
    }
}
