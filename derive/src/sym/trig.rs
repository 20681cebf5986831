//! Sine and cosine of one argument together, for the numeric tapes.
//!
//! A simulation evaluates `sin(alpha)` and `cos(alpha)` at every integrator
//! stage; the platform's `sin` and `cos` reduce the argument twice and are
//! not inlined (a seventh of the identification's time went to them). Here the
//! argument is reduced once modulo `pi/2` (Cody-Waite in 33-bit parts of
//! `pi/2`, two or three rounds as fdlibm's medium case, for
//! `|x| < 2^20 pi/2`; larger or non-finite arguments go to the platform) and
//! the two kernels are the classic
//! fdlibm/musl minimax polynomials on `[-pi/4, pi/4]`, whose error is below
//! one unit in the last place.
//!
//! The kernels and the reduction constants (as bit patterns, exact) are
//! those of fdlibm
//! (`k_sin.c`, `k_cos.c`, `e_rem_pio2.c`):
//! Copyright (C) 1993 by Sun Microsystems, Inc. All rights reserved.
//! Developed at SunPro, a Sun Microsystems, Inc. business.
//! Permission to use, copy, modify, and distribute this software is freely
//! granted, provided that this notice is preserved.

const S1: f64 = f64::from_bits(0xbfc5_5555_5555_5549);
const S2: f64 = f64::from_bits(0x3f81_1111_1110_f8a6);
const S3: f64 = f64::from_bits(0xbf2a_01a0_19c1_61d5);
const S4: f64 = f64::from_bits(0x3ec7_1de3_57b1_fe7d);
const S5: f64 = f64::from_bits(0xbe5a_e5e6_8a2b_9ceb);
const S6: f64 = f64::from_bits(0x3de5_d93a_5acf_d57c);

const C1: f64 = f64::from_bits(0x3fa5_5555_5555_554c);
const C2: f64 = f64::from_bits(0xbf56_c16c_16c1_5177);
const C3: f64 = f64::from_bits(0x3efa_01a0_19cb_1590);
const C4: f64 = f64::from_bits(0xbe92_7e4f_809c_52ad);
const C5: f64 = f64::from_bits(0x3e21_ee9e_bdb4_b1c4);
const C6: f64 = f64::from_bits(0xbda8_fae9_be88_38d4);

/// `2/pi`.
const INV_PIO2: f64 = f64::from_bits(0x3fe4_5f30_6dc9_c883);
/// First 33 bits of `pi/2`.
const PIO2_1: f64 = f64::from_bits(0x3ff9_21fb_5440_0000);
/// Second 33 bits of `pi/2`.
const PIO2_2: f64 = f64::from_bits(0x3dd0_b461_1a60_0000);
/// `pi/2 - (PIO2_1 + PIO2_2)`.
const PIO2_2T: f64 = f64::from_bits(0x3ba3_198a_2e03_7073);
/// Third 33 bits of `pi/2`.
const PIO2_3: f64 = f64::from_bits(0x3ba3_198a_2e00_0000);
/// `pi/2 - (PIO2_1 + PIO2_2 + PIO2_3)`.
const PIO2_3T: f64 = f64::from_bits(0x397b_839a_2520_49c1);
/// Adding and subtracting this rounds to an integer (`1.5 * 2^52`).
const TO_INT: f64 = 1.5 / f64::EPSILON;
/// `pi/4`, below which no reduction is needed.
const PIO4: f64 = std::f64::consts::FRAC_PI_4;
/// Above this the two-round reduction is not exact enough.
const MEDIUM: f64 = 1_048_576.0 * std::f64::consts::FRAC_PI_2;

/// `sin(x + y)` for `|x + y| <= pi/4`, `y` the tail of a reduced argument.
#[inline(always)]
fn k_sin(x: f64, y: f64) -> f64 {
    let z = x * x;
    let w = z * z;
    let r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
    let v = z * x;
    x - ((z * (0.5 * y - v * r) - y) - v * S1)
}

/// `cos(x + y)` for `|x + y| <= pi/4`.
#[inline(always)]
fn k_cos(x: f64, y: f64) -> f64 {
    let z = x * x;
    let w = z * z;
    let r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    w + (((1.0 - w) - hz) + (z * r - x * y))
}

/// `(sin x, cos x)`, within one unit in the last place of the exact values.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    let ax = x.abs();
    if ax <= PIO4 {
        return (k_sin(x, 0.0), k_cos(x, 0.0));
    }
    // non-finite and huge arguments go to the platform
    if ax.is_nan() || ax >= MEDIUM {
        return x.sin_cos();
    }
    let f = x * INV_PIO2 + TO_INT - TO_INT;
    // x - f pi/2 in two rounds (fdlibm's `__rem_pio2`, medium case): f times
    // a 33-bit part of pi/2 is exact, the rounding of each subtraction is
    // carried in `w`; a third round where the result cancelled 49 bits
    let r0 = x - f * PIO2_1;
    let w2 = f * PIO2_2;
    let mut r = r0 - w2;
    let mut w = f * PIO2_2T - ((r0 - r) - w2);
    let mut y0 = r - w;
    let exponent = |v: f64| ((v.to_bits() >> 52) & 0x7ff) as i64;
    if exponent(x) - exponent(y0) > 49 {
        let t = r;
        let w3 = f * PIO2_3;
        r = t - w3;
        w = f * PIO2_3T - ((t - r) - w3);
        y0 = r - w;
    }
    let y1 = (r - y0) - w;
    let (s, c) = (k_sin(y0, y1), k_cos(y0, y1));
    match (f as i64) & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// `sin x` ([`sin_cos`]).
#[inline]
pub fn sin(x: f64) -> f64 {
    sin_cos(x).0
}

/// `cos x` ([`sin_cos`]).
#[inline]
pub fn cos(x: f64) -> f64 {
    sin_cos(x).1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place of `b`.
    fn ulps(a: f64, b: f64) -> f64 {
        if a == b {
            return 0.0;
        }
        let spacing = f64::from_bits(b.abs().to_bits() + 1) - b.abs();
        (a - b).abs() / spacing.max(f64::MIN_POSITIVE)
    }

    /// Checked against the platform's (glibc's correctly rounded in
    /// practice) `sin` and `cos`: at most one unit in the last place apart.
    fn check(x: f64) {
        let (s, c) = sin_cos(x);
        assert!(
            ulps(s, x.sin()) <= 1.0,
            "sin({x:e}) = {s:e} vs {:e}",
            x.sin()
        );
        assert!(
            ulps(c, x.cos()) <= 1.0,
            "cos({x:e}) = {c:e} vs {:e}",
            x.cos()
        );
    }

    #[test]
    fn within_one_ulp_of_the_platform() {
        // a fixed linear congruential sequence over several scales
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for scale in [1e-8, 0.5, 1.0, 4.0, 10.0, 100.0, 1e4, 1e6, 1e7] {
            for _ in 0..20_000 {
                check((2.0 * next() - 1.0) * scale);
            }
        }
    }

    #[test]
    fn near_multiples_of_half_pi() {
        // the reduction cancels most there: the neighbours of k pi/2 in f64
        for k in 1..2000i64 {
            let x = k as f64 * std::f64::consts::FRAC_PI_2;
            let mut v = x;
            for _ in 0..4 {
                check(v);
                check(-v);
                v = f64::from_bits(v.to_bits() + 1);
            }
            let mut v = x;
            for _ in 0..4 {
                v = f64::from_bits(v.to_bits() - 1);
                check(v);
            }
        }
        // and large multiples, up to the medium range's end
        for k in [65_537i64, 300_001, 667_000, 1_000_003, 1_048_575] {
            let x = k as f64 * std::f64::consts::FRAC_PI_2;
            let mut v = f64::from_bits(x.to_bits() - 3);
            for _ in 0..7 {
                check(v);
                v = f64::from_bits(v.to_bits() + 1);
            }
        }
    }

    #[test]
    fn special_values() {
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        assert!(sin_cos(-0.0).0.is_sign_negative());
        assert!(sin_cos(f64::NAN).0.is_nan() && sin_cos(f64::NAN).1.is_nan());
        assert!(sin_cos(f64::INFINITY).0.is_nan());
        check(1e300);
        check(f64::MIN_POSITIVE);
        check(MEDIUM);
        check(-MEDIUM * 0.999_999);
    }
}
