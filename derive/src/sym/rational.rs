//! Exact rational numbers on `i128`, with checked arithmetic.
//!
//! Every operation that could overflow returns `Option`; callers fall back to
//! floating point (see [`crate::sym::Expr::float`]) when exactness cannot be kept.

use std::cmp::Ordering;
use std::fmt;

/// An exact rational `num/den` in lowest terms with `den > 0`.
#[derive(Copy, Clone, PartialEq, Eq, Hash, Debug)]
pub struct Rational {
    num: i128,
    den: i128,
}

fn gcd(mut a: i128, mut b: i128) -> i128 {
    a = a.abs();
    b = b.abs();
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

impl Rational {
    /// Zero.
    pub const ZERO: Rational = Rational { num: 0, den: 1 };
    /// One.
    pub const ONE: Rational = Rational { num: 1, den: 1 };
    /// Minus one.
    pub const MINUS_ONE: Rational = Rational { num: -1, den: 1 };

    /// `num/den` reduced; `None` if `den == 0` or on overflow.
    pub fn new(num: i128, den: i128) -> Option<Rational> {
        if den == 0 {
            return None;
        }
        let g = gcd(num, den);
        let (mut n, mut d) = if g > 1 {
            (num / g, den / g)
        } else {
            (num, den)
        };
        if d < 0 {
            n = n.checked_neg()?;
            d = d.checked_neg()?;
        }
        Some(Rational { num: n, den: d })
    }

    /// An integer.
    pub const fn int(n: i128) -> Rational {
        Rational { num: n, den: 1 }
    }

    /// Numerator (sign carrier).
    pub fn numer(self) -> i128 {
        self.num
    }

    /// Denominator (always positive).
    pub fn denom(self) -> i128 {
        self.den
    }

    /// True if zero.
    pub fn is_zero(self) -> bool {
        self.num == 0
    }

    /// True if one.
    pub fn is_one(self) -> bool {
        self.num == 1 && self.den == 1
    }

    /// True if an integer.
    pub fn is_integer(self) -> bool {
        self.den == 1
    }

    /// True if negative.
    pub fn is_negative(self) -> bool {
        self.num < 0
    }

    /// The integer value if this is an integer that fits in `i64`.
    pub fn to_i64(self) -> Option<i64> {
        if self.den == 1 {
            i64::try_from(self.num).ok()
        } else {
            None
        }
    }

    /// Nearest `f64`.
    pub fn to_f64(self) -> f64 {
        self.num as f64 / self.den as f64
    }

    /// Checked sum.
    pub fn checked_add(self, o: Rational) -> Option<Rational> {
        let g = gcd(self.den, o.den);
        let l = (self.den / g).checked_mul(o.den)?;
        let a = self.num.checked_mul(l / self.den)?;
        let b = o.num.checked_mul(l / o.den)?;
        Rational::new(a.checked_add(b)?, l)
    }

    /// Checked difference.
    pub fn checked_sub(self, o: Rational) -> Option<Rational> {
        self.checked_add(o.checked_neg()?)
    }

    /// Checked negation.
    pub fn checked_neg(self) -> Option<Rational> {
        Some(Rational {
            num: self.num.checked_neg()?,
            den: self.den,
        })
    }

    /// Checked product.
    pub fn checked_mul(self, o: Rational) -> Option<Rational> {
        let g1 = gcd(self.num, o.den).max(1);
        let g2 = gcd(o.num, self.den).max(1);
        let n = (self.num / g1).checked_mul(o.num / g2)?;
        let d = (self.den / g2).checked_mul(o.den / g1)?;
        Rational::new(n, d)
    }

    /// Checked reciprocal (`None` for zero).
    pub fn checked_recip(self) -> Option<Rational> {
        Rational::new(self.den, self.num)
    }

    /// Checked quotient.
    pub fn checked_div(self, o: Rational) -> Option<Rational> {
        self.checked_mul(o.checked_recip()?)
    }

    /// Checked integer power (negative exponents allowed for nonzero bases).
    pub fn checked_powi(self, e: i64) -> Option<Rational> {
        let base = if e < 0 { self.checked_recip()? } else { self };
        let mut n = e.unsigned_abs();
        let mut acc = Rational::ONE;
        let mut b = base;
        while n > 0 {
            if n & 1 == 1 {
                acc = acc.checked_mul(b)?;
            }
            n >>= 1;
            if n > 0 {
                b = b.checked_mul(b)?;
            }
        }
        Some(acc)
    }

    /// Exact `self^(p/q)` if the result is rational (e.g. `(4/9)^(1/2) = 2/3`).
    pub fn checked_pow_rational(self, e: Rational) -> Option<Rational> {
        if e.is_integer() {
            return self.checked_powi(i64::try_from(e.num).ok()?);
        }
        if self.num < 0 {
            return None;
        }
        let q = u32::try_from(e.den).ok()?;
        let rn = exact_root(self.num, q)?;
        let rd = exact_root(self.den, q)?;
        Rational::new(rn, rd)?.checked_powi(i64::try_from(e.num).ok()?)
    }

    /// Absolute value.
    pub fn abs(self) -> Rational {
        Rational {
            num: self.num.abs(),
            den: self.den,
        }
    }

    /// Parse a decimal literal such as `9.98e-4`, `70`, `0.5`, `1E3` exactly.
    pub fn from_decimal_str(s: &str) -> Option<Rational> {
        let s = s.trim();
        let (mant, exp) = match s.find(['e', 'E']) {
            Some(i) => (&s[..i], s[i + 1..].parse::<i32>().ok()?),
            None => (s, 0),
        };
        let (neg, mant) = match mant.strip_prefix('-') {
            Some(m) => (true, m),
            None => (false, mant.strip_prefix('+').unwrap_or(mant)),
        };
        let (int_part, frac_part) = match mant.find('.') {
            Some(i) => (&mant[..i], &mant[i + 1..]),
            None => (mant, ""),
        };
        if int_part.is_empty() && frac_part.is_empty() {
            return None;
        }
        if !int_part.bytes().all(|b| b.is_ascii_digit())
            || !frac_part.bytes().all(|b| b.is_ascii_digit())
        {
            return None;
        }
        let digits = format!("{int_part}{frac_part}");
        let digits = digits.trim_start_matches('0');
        let mut num: i128 = if digits.is_empty() {
            0
        } else {
            digits.parse().ok()?
        };
        if neg {
            num = -num;
        }
        let scale = exp - frac_part.len() as i32;
        let ten = Rational::int(10);
        let factor = ten.checked_powi(scale as i64)?;
        Rational::int(num).checked_mul(factor)
    }

    /// Best rational approximation of a finite `f64` with denominator at most
    /// `max_den` (continued fractions); `None` for non-finite input.
    pub fn approximate(x: f64, max_den: i128) -> Option<Rational> {
        if !x.is_finite() || x.abs() > 1e30 {
            return None;
        }
        let (mut p0, mut q0, mut p1, mut q1) = (0i128, 1i128, 1i128, 0i128);
        let mut v = x;
        for _ in 0..64 {
            let a = v.floor();
            let ai = a as i128;
            let p2 = ai.checked_mul(p1)?.checked_add(p0)?;
            let q2 = ai.checked_mul(q1)?.checked_add(q0)?;
            if q2 > max_den {
                break;
            }
            p0 = p1;
            q0 = q1;
            p1 = p2;
            q1 = q2;
            let frac = v - a;
            if frac.abs() < 1e-300 || (p1 as f64 / q1 as f64 - x).abs() <= f64::EPSILON * x.abs() {
                break;
            }
            v = 1.0 / frac;
        }
        Rational::new(p1, q1)
    }
}

fn exact_root(n: i128, q: u32) -> Option<i128> {
    if n < 0 {
        return None;
    }
    if n < 2 {
        return Some(n);
    }
    let guess = (n as f64).powf(1.0 / q as f64).round() as i128;
    [guess - 1, guess, guess + 1]
        .into_iter()
        .find(|&r| r >= 0 && r.checked_pow(q) == Some(n))
}

impl PartialOrd for Rational {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Rational {
    fn cmp(&self, o: &Self) -> Ordering {
        match (self.num.checked_mul(o.den), o.num.checked_mul(self.den)) {
            (Some(a), Some(b)) => a.cmp(&b),
            _ => cmp_frac(self.num, self.den, o.num, o.den),
        }
    }
}

/// Exact comparison of `a/b` and `c/d` (`b, d > 0`) without overflow, by
/// comparing integer parts and then the reciprocals of the fractional parts.
fn cmp_frac(mut a: i128, mut b: i128, mut c: i128, mut d: i128) -> Ordering {
    loop {
        let (qa, ra) = (a.div_euclid(b), a.rem_euclid(b));
        let (qc, rc) = (c.div_euclid(d), c.rem_euclid(d));
        if qa != qc {
            return qa.cmp(&qc);
        }
        match (ra == 0, rc == 0) {
            (true, true) => return Ordering::Equal,
            (true, false) => return Ordering::Less,
            (false, true) => return Ordering::Greater,
            (false, false) => {}
        }
        // ra/b < rc/d  <=>  d/rc < b/ra
        (a, b, c, d) = (d, rc, b, ra);
    }
}

impl fmt::Display for Rational {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.den == 1 {
            write!(f, "{}", self.num)
        } else {
            write!(f, "{}/{}", self.num, self.den)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimal_literals_are_exact() {
        assert_eq!(
            Rational::from_decimal_str("9.98e-4"),
            Rational::new(998, 1_000_000)
        );
        assert_eq!(Rational::from_decimal_str("0.5"), Rational::new(1, 2));
        assert_eq!(Rational::from_decimal_str("70"), Some(Rational::int(70)));
        assert_eq!(Rational::from_decimal_str(".25"), Rational::new(1, 4));
        assert_eq!(Rational::from_decimal_str("1E3"), Some(Rational::int(1000)));
        assert_eq!(Rational::from_decimal_str("abc"), None);
    }

    #[test]
    fn arithmetic() {
        let a = Rational::new(1, 3).unwrap();
        let b = Rational::new(1, 6).unwrap();
        assert_eq!(a.checked_add(b), Rational::new(1, 2));
        assert_eq!(a.checked_mul(b), Rational::new(1, 18));
        assert_eq!(a.checked_powi(-2), Some(Rational::int(9)));
        assert_eq!(
            Rational::new(4, 9)
                .unwrap()
                .checked_pow_rational(Rational::new(1, 2).unwrap()),
            Rational::new(2, 3)
        );
        assert_eq!(
            Rational::int(2).checked_pow_rational(Rational::new(1, 2).unwrap()),
            None
        );
        assert_eq!(Rational::approximate(0.75, 1000), Rational::new(3, 4));
        // Ordering stays exact when the cross products overflow.
        let big = i128::MAX / 3;
        let x = Rational::new(big, big - 1).unwrap();
        let y = Rational::new(big - 1, big - 2).unwrap();
        assert_eq!(x.cmp(&y), Ordering::Less);
        assert_eq!(y.cmp(&x), Ordering::Greater);
        assert_eq!(x.cmp(&x), Ordering::Equal);
        assert_eq!(x.checked_neg().unwrap().cmp(&y), Ordering::Less);
    }
}
