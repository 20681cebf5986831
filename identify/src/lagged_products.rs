//! Lagged products `sum_t x[t] x[t + k]`, `k = 0..=L`, of a long series:
//! the unnormalised autocorrelation the residual tests need out to a
//! residual's correlation reach ([`crate::residual_tests`]), which for a
//! slow model error is up to a quarter of the record.
//!
//! Summed directly that costs `N (L + 1)` products: 2.5e13 for a 1e7-sample
//! record and `L = N / 4` (hours). Above [`DIRECT_PRODUCTS`] the sums go
//! through the FFT instead: the record in blocks of `b >= L + 1` samples
//! (a power of two), each block correlated with the `2b` samples from its
//! start by one complex transform of `2b` points (the block and its span
//! packed as real and imaginary parts) and one inverse, so the work is
//! `O(N log b)` and the memory `2b` complex values (at most the record's
//! length), whatever `L`. Circular wrap-around cannot reach the sums: a
//! block's samples are zero past `b` and `k + t < 2b`.
//!
//! The two ways give the same sums up to rounding (relative to the lag-0
//! sum, about `1e-16 log2(2b)` per block; the test below checks 1e-12).

/// Direct sums up to this many products (about 0.1 s at a nanosecond
/// each): below it they are fast anyway and keep the short records' results
/// bit for bit what they were; above it the FFT's `O(N log b)` wins.
pub const DIRECT_PRODUCTS: usize = 100_000_000;

/// `sum_t x[t] x[t + k]` for `k` in `0..=lags` (lags past the series give
/// zero).
pub fn lagged_products(x: &[f64], lags: usize) -> Vec<f64> {
    if x.len().saturating_mul(lags + 1) <= DIRECT_PRODUCTS {
        direct(x, lags)
    } else {
        by_fft(x, lags)
    }
}

/// The direct sums (each in sample order).
fn direct(x: &[f64], lags: usize) -> Vec<f64> {
    let n = x.len();
    (0..=lags)
        .map(|k| {
            if k >= n {
                return 0.0;
            }
            x[..n - k].iter().zip(&x[k..]).map(|(a, b)| a * b).sum()
        })
        .collect()
}

/// The sums through the FFT, block by block (see the module docs).
fn by_fft(x: &[f64], lags: usize) -> Vec<f64> {
    let n = x.len();
    let mut out = vec![0.0; lags + 1];
    let reach = lags.min(n.saturating_sub(1));
    if n == 0 {
        return out;
    }
    let b = (reach + 1).next_power_of_two();
    let m = 2 * b;
    let mut z = vec![(0.0, 0.0); m];
    for s in (0..n).step_by(b) {
        // z = a + i c: a the block (zero past b), c the span from its start
        for (j, zj) in z.iter_mut().enumerate() {
            let c = x.get(s + j).copied().unwrap_or(0.0);
            let a = if j < b { c } else { 0.0 };
            *zj = (a, c);
        }
        fft(&mut z, false);
        // A_k = (Z_k + conj Z_{m-k}) / 2, C_k = (Z_k - conj Z_{m-k}) / 2i;
        // the correlation's spectrum conj(A_k) C_k, and conj of it at m - k
        for k in 0..=m / 2 {
            let (zk, zm) = (z[k], z[(m - k) % m]);
            let a = (0.5 * (zk.0 + zm.0), 0.5 * (zk.1 - zm.1));
            let c = (0.5 * (zk.1 + zm.1), -0.5 * (zk.0 - zm.0));
            let p = (a.0 * c.0 + a.1 * c.1, a.0 * c.1 - a.1 * c.0);
            z[k] = p;
            z[(m - k) % m] = (p.0, -p.1);
        }
        fft(&mut z, true);
        for (o, v) in out.iter_mut().zip(&z).take(reach + 1) {
            *o += v.0 / m as f64;
        }
    }
    out
}

/// In-place radix-2 FFT of `z` (length a power of two), `sum_t z_t
/// e^(-2 pi i k t / m)`, or without the minus sign and unscaled with
/// `inverse`. Twiddles from `sin_cos` of each angle (no recurrence: no
/// error growth along a stage).
fn fft(z: &mut [(f64, f64)], inverse: bool) {
    let m = z.len();
    debug_assert!(m.is_power_of_two());
    let bits = m.trailing_zeros();
    if bits == 0 {
        return;
    }
    for i in 0..m {
        let j = i.reverse_bits() >> (usize::BITS - bits);
        if j > i {
            z.swap(i, j);
        }
    }
    let sign = if inverse { 1.0 } else { -1.0 };
    let mut len = 2;
    while len <= m {
        let half = len / 2;
        let step = sign * 2.0 * std::f64::consts::PI / len as f64;
        for j in 0..half {
            let (s, c) = (step * j as f64).sin_cos();
            for start in (0..m).step_by(len) {
                let (u, v) = (z[start + j], z[start + j + half]);
                let t = (v.0 * c - v.1 * s, v.0 * s + v.1 * c);
                z[start + j] = (u.0 + t.0, u.1 + t.1);
                z[start + j + half] = (u.0 - t.0, u.1 - t.1);
            }
        }
        len *= 2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn series(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        let mut prev = 0.0;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                // a coloured series with an offset: slow, like a model error
                prev = 0.95 * prev + ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
                prev + 0.3
            })
            .collect()
    }

    proptest! {
        /// The FFT's sums equal the direct ones (the independent
        /// computation: the definition summed term by term) to 1e-12 of
        /// the lag-0 sum, for any length and lags (short, past the series,
        /// a power of two and not).
        #[test]
        fn fft_equals_direct(n in 1usize..3000, lags in 0usize..1200, seed in 0u64..1000) {
            let x = series(n, seed);
            let (d, f) = (direct(&x, lags), by_fft(&x, lags));
            prop_assert_eq!(d.len(), f.len());
            for (k, (a, b)) in d.iter().zip(&f).enumerate() {
                prop_assert!((a - b).abs() <= 1e-12 * d[0], "lag {}: {} vs {}", k, a, b);
            }
        }
    }

    /// Short series take the direct sums (bit for bit); long ones with
    /// many lags the FFT.
    #[test]
    fn dispatch() {
        let x = series(1000, 1);
        assert_eq!(lagged_products(&x, 50), direct(&x, 50));
        let long = series(DIRECT_PRODUCTS / 100 + 1, 2);
        let f = lagged_products(&long, 99);
        // two of the lags summed term by term (all would be the 1e8
        // products the dispatch avoids)
        let at = |k: usize| -> f64 { long.iter().zip(&long[k..]).map(|(a, b)| a * b).sum() };
        for k in [0, 99] {
            assert!(
                (f[k] - at(k)).abs() <= 1e-12 * at(0),
                "{} vs {}",
                f[k],
                at(k)
            );
        }
    }
}
