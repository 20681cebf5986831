//! Residual analysis like MATLAB's `resid`: is what the model leaves white
//! noise, and is it independent of the input?
//!
//! For a residual `e` (measured minus predicted) of `N` samples:
//! - the normalised autocorrelation `r_e(tau) = sum e_t e_{t+tau} / sum e_t^2`
//!   for `tau = 1..L`;
//! - the normalised cross-correlation with each input `u` (mean removed),
//!   `r_eu(tau) = sum e_{t+tau} u_t / sqrt(sum e^2 sum u^2)` for `tau = -L..L`
//!   (positive lags: the residual after the input, where a missing dynamic
//!   response shows).
//!
//! A simulation residual of a real rig is never white: a model error is slow,
//! and the whiteness test of MATLAB's `resid` (every lag within
//! `2.576/sqrt(N)`) fails on every real record, telling nothing. What is
//! reported instead:
//! - the residual's **correlation time** `tau` (samples;
//!   [`crate::decision::correlation_time`]): 1 for white noise, the number
//!   of samples that carry one independent value otherwise (`N / tau` is
//!   the effective sample count the decision rule uses). `white` means
//!   `tau` below 2: within what a white residual's estimate gives.
//! - the **independence from each input**, tested with bands that account
//!   for the residual's and the input's own correlation: for two
//!   independent stationary series the cross-correlation at any lag is
//!   approximately normal with variance `(1/N) sum_j rho_e(j) rho_u(j)`
//!   (Bartlett's formula), so the 99 % band is `2.576` times its square
//!   root (`2.576/sqrt(N)` for white series). A residual that depends on
//!   the input beyond its own colour (a missing input dynamic, a delay)
//!   leaves that band; one whose colour comes from a slow model error does
//!   not. The test passes when at most one lag leaves the band (with 51
//!   lags and 1 % per lag, one excursion is within what chance gives).
//!
//! Lags are in samples, as in MATLAB; the physical time they span is
//! reported too.

use serde::Serialize;

use crate::lagged_products::lagged_products;

/// Standard normal quantile of 99.5 % (two-sided 99 % band).
pub const Z99: f64 = 2.5758293035489004;

/// Default number of lags (MATLAB's `resid` uses 25).
pub const DEFAULT_LAGS: usize = 25;

/// Cross-correlation of a residual with one input.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CrossCorrelation {
    /// Input name.
    pub input: String,
    /// `r_eu(tau)` for `tau = -L..=L`.
    pub values: Vec<f64>,
    /// Half-width of its 99 % band (Bartlett's, see the module docs).
    pub band: f64,
    /// Lags outside the band.
    pub outside: usize,
    /// True when at most one lag is outside.
    pub independent: bool,
}

/// The residual tests of one channel of one experiment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ResidualTest {
    /// Experiment name.
    pub experiment: String,
    /// Channel (coordinate) name.
    pub channel: String,
    /// Samples used.
    pub samples: usize,
    /// Number of lags `L`.
    pub lags: usize,
    /// Time spanned by `L` lags (s, median sample period times `L`).
    pub lag_span: f64,
    /// `r_e(tau)` for `tau = 0..=L` (`r_e(0) = 1`).
    pub autocorrelation: Vec<f64>,
    /// Half-width of the 99 % band of a white residual's autocorrelation
    /// (drawn with it).
    pub band: f64,
    /// Lags `1..=L` outside that band.
    pub outside: usize,
    /// The residual's correlation time in samples.
    pub correlation_time: f64,
    /// True when the correlation time is below 2 samples.
    pub white: bool,
    /// Cross-correlations with the inputs.
    pub cross: Vec<CrossCorrelation>,
}

impl CrossCorrelation {
    /// `(lag, r_eu(lag))` for `lag = -L..=L`, as drawn.
    pub fn points(&self) -> Vec<(f64, f64)> {
        let l = self.half_width();
        self.values
            .iter()
            .enumerate()
            .map(|(k, v)| (k as f64 - l, *v))
            .collect()
    }

    /// `L`: the largest lag either way.
    pub fn half_width(&self) -> f64 {
        (self.values.len() as f64 - 1.0) / 2.0
    }

    /// `independent` or `correlated`.
    pub fn verdict(&self) -> &'static str {
        if self.independent {
            "independent"
        } else {
            "correlated"
        }
    }
}

impl ResidualTest {
    /// `(lag, r_e(lag))` for `lag = 1..=L`, as drawn (lag 0 is 1 by
    /// definition).
    pub fn autocorrelation_points(&self) -> Vec<(f64, f64)> {
        self.autocorrelation
            .iter()
            .enumerate()
            .skip(1)
            .map(|(k, v)| (k as f64, *v))
            .collect()
    }

    /// One line: `alpha: white (1 of 25 lags outside the 99 % band);
    /// independent of Vm (0 of 51)`.
    pub fn summary(&self) -> String {
        let dt = if self.lags > 0 {
            self.lag_span / self.lags as f64
        } else {
            0.0
        };
        let mut s = format!(
            "{}: correlation time {:.1} samples ({:.3} s){}",
            self.channel,
            self.correlation_time,
            self.correlation_time * dt,
            if self.white { ", white" } else { "" },
        );
        for c in &self.cross {
            s.push_str(&format!(
                "; {} {} ({} of {} lags outside the 99 % band for its colour)",
                if c.independent {
                    "independent of"
                } else {
                    "correlated with"
                },
                c.input,
                c.outside,
                c.values.len()
            ));
        }
        s
    }
}

/// Run the tests on `residual` (non-finite samples are dropped together
/// with the inputs at the same instants) against `inputs`, with `lags` lags
/// and median sample period `dt`.
pub fn residual_test(
    experiment: &str,
    channel: &str,
    residual: &[f64],
    inputs: &[(&str, &[f64])],
    lags: usize,
    dt: f64,
) -> ResidualTest {
    // the finite samples: the residual itself when all are (no copies of a
    // long record's residual and of the indices)
    let keep: Option<Vec<usize>> = if residual.iter().all(|v| v.is_finite()) {
        None
    } else {
        Some(
            (0..residual.len())
                .filter(|&k| residual[k].is_finite())
                .collect(),
        )
    };
    let e: std::borrow::Cow<[f64]> = match &keep {
        None => residual.into(),
        Some(keep) => keep.iter().map(|&k| residual[k]).collect(),
    };
    let e = &e[..];
    let n = e.len();
    let lags = lags.min(n.saturating_sub(1));
    let band = Z99 / (n.max(1) as f64).sqrt();
    let e0: f64 = e.iter().map(|v| v * v).sum();
    let auto: Vec<f64> = (0..=lags)
        .map(|tau| {
            if e0 == 0.0 {
                if tau == 0 {
                    1.0
                } else {
                    0.0
                }
            } else {
                (0..n - tau).map(|t| e[t] * e[t + tau]).sum::<f64>() / e0
            }
        })
        .collect();
    let outside = auto.iter().skip(1).filter(|r| r.abs() > band).count();
    let tau = crate::decision::correlation_time(e);
    // the residual's autocorrelation out to where it has died away (its
    // correlation time's reach), for Bartlett's band
    let reach = ((4.0 * tau).ceil() as usize).clamp(lags, (n / 4).max(lags));
    // lagged products out to the reach (a quarter of the record for a slow
    // model error: through the FFT, [`crate::lagged_products`])
    let rho_of = |x: &[f64], x0: f64| -> Vec<f64> {
        if x0 == 0.0 {
            return vec![0.0; reach + 1];
        }
        lagged_products(x, reach).iter().map(|p| p / x0).collect()
    };
    let rho_e = rho_of(e, e0);
    let cross = inputs
        .iter()
        .map(|(name, u)| {
            let at = |k: usize| u.get(k).copied().unwrap_or(0.0);
            let picked = || -> Box<dyn Iterator<Item = f64> + '_> {
                match &keep {
                    None => Box::new((0..n).map(at)),
                    Some(keep) => Box::new(keep.iter().map(move |&k| at(k))),
                }
            };
            let mean = picked().sum::<f64>() / n.max(1) as f64;
            let u: Vec<f64> = picked().map(|v| v - mean).collect();
            let u0: f64 = u.iter().map(|v| v * v).sum();
            let den = (e0 * u0).sqrt();
            let values: Vec<f64> = (-(lags as i64)..=lags as i64)
                .map(|tau| {
                    if den == 0.0 {
                        return 0.0;
                    }
                    let mut s = 0.0;
                    for t in 0..n as i64 {
                        let te = t + tau;
                        if te >= 0 && te < n as i64 {
                            s += e[te as usize] * u[t as usize];
                        }
                    }
                    s / den
                })
                .collect();
            // Bartlett: var = (1/N) sum_j rho_e(j) rho_u(j), j = -reach..reach
            let rho_u = rho_of(&u, u0);
            let var = (rho_e[0] * rho_u[0]
                + 2.0 * (1..=reach).map(|j| rho_e[j] * rho_u[j]).sum::<f64>())
            .max(1.0)
                / n.max(1) as f64;
            let cband = Z99 * var.sqrt();
            let out = values.iter().filter(|r| r.abs() > cband).count();
            CrossCorrelation {
                input: name.to_string(),
                values,
                band: cband,
                outside: out,
                independent: out <= 1,
            }
        })
        .collect();
    ResidualTest {
        experiment: experiment.to_string(),
        channel: channel.to_string(),
        samples: n,
        lags,
        lag_span: lags as f64 * dt,
        autocorrelation: auto,
        band,
        outside,
        correlation_time: tau,
        white: tau < 2.0,
        cross,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    /// White noise passes; a filtered one fails whiteness; a residual made
    /// of the delayed input fails independence at the right lag.
    #[test]
    fn white_coloured_and_input_correlated() {
        let e = noise(5000, 1);
        let u = noise(5000, 2);
        let t = residual_test("x", "a", &e, &[("u", &u)], 25, 0.002);
        assert!(t.white, "{}", t.summary());
        assert!(t.cross[0].independent, "{}", t.summary());
        assert!((t.band - Z99 / 5000f64.sqrt()).abs() < 1e-15);
        // first-order low-pass: strongly correlated at lag 1
        let mut c = vec![0.0; 5000];
        for k in 1..5000 {
            c[k] = 0.9 * c[k - 1] + e[k];
        }
        let t = residual_test("x", "a", &c, &[("u", &u)], 25, 0.002);
        assert!(!t.white);
        assert!((t.autocorrelation[1] - 0.9).abs() < 0.05);
        // AR(1) with coefficient 0.9: correlation time (1 + 0.9)/(1 - 0.9)
        assert!((t.correlation_time - 19.0).abs() < 6.0, "{}", t.summary());
        // a coloured residual and a coloured input, independent: the
        // widened band keeps it independent (the white band would not)
        let mut cu = vec![0.0; 5000];
        for k in 1..5000 {
            cu[k] = 0.9 * cu[k - 1] + u[k];
        }
        let t = residual_test("x", "a", &c, &[("u", &cu)], 25, 0.002);
        assert!(t.cross[0].independent, "{}", t.summary());
        assert!(
            t.cross[0].band > 2.0 * Z99 / 5000f64.sqrt(),
            "{}",
            t.cross[0].band
        );
        // residual = input 3 samples earlier (plus noise): cross peak at +3
        let r: Vec<f64> = (0..5000)
            .map(|k| if k >= 3 { u[k - 3] } else { 0.0 } + 0.1 * e[k])
            .collect();
        let t = residual_test("x", "a", &r, &[("u", &u)], 25, 0.002);
        let peak = t.cross[0]
            .values
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map(|(i, _)| i as i64 - 25)
            .expect("lags");
        assert_eq!(peak, 3);
        assert!(!t.cross[0].independent);
    }
}
