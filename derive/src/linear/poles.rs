//! Eigenvalues (poles) of a state matrix, and parsing of pole lists.

use nalgebra::{Complex, DMatrix, Schur};
use serde::{Deserialize, Serialize};

use super::error::{check_finite, LinearError};

/// A point of the complex plane, serialised as `{"re": .., "im": ..}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pole {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl Pole {
    /// A pole from its real and imaginary parts.
    pub fn new(re: f64, im: f64) -> Self {
        Pole { re, im }
    }

    /// A real pole.
    pub fn real(re: f64) -> Self {
        Pole { re, im: 0.0 }
    }

    /// As a nalgebra complex number.
    pub fn to_complex(self) -> Complex<f64> {
        Complex::new(self.re, self.im)
    }

    /// Modulus.
    pub fn abs(self) -> f64 {
        self.re.hypot(self.im)
    }
}

impl From<Complex<f64>> for Pole {
    fn from(c: Complex<f64>) -> Self {
        Pole { re: c.re, im: c.im }
    }
}

/// Relative size under which an imaginary part is considered numerical noise
/// (relative to the largest eigenvalue modulus).
const IMAG_SNAP: f64 = 1e-12;

/// Eigenvalues of the square matrix `a`, in the canonical order of
/// [`canonicalize_poles`]: sorted by real part then imaginary part,
/// imaginary parts below `1e-12 * max|lambda|` set to zero, complex pairs
/// made exactly conjugate.
pub fn poles(a: &DMatrix<f64>) -> Result<Vec<Pole>, LinearError> {
    let n = a.nrows();
    if n == 0 {
        return Err(LinearError::EmptyMatrix { matrix: "A" });
    }
    if a.ncols() != n {
        return Err(LinearError::NotSquare {
            matrix: "A",
            rows: n,
            cols: a.ncols(),
        });
    }
    check_finite("A", a)?;
    let schur = Schur::try_new(a.clone(), f64::EPSILON, 1000 + 200 * n)
        .ok_or(LinearError::EigenvaluesFailed { n })?;
    let eig: Vec<Pole> = schur
        .complex_eigenvalues()
        .iter()
        .map(|c| Pole::from(*c))
        .collect();
    Ok(canonicalize_poles(eig))
}

/// Puts a list of eigenvalues of a real matrix into canonical form (see [`poles`]).
///
/// Each pole with positive imaginary part is paired with the closest unused
/// pole with negative imaginary part; both are replaced by the averaged pair
/// `re ± i im`. Poles without partner are left unchanged.
pub fn canonicalize_poles(mut p: Vec<Pole>) -> Vec<Pole> {
    let scale = p.iter().map(|z| z.abs()).fold(0.0, f64::max);
    for z in p.iter_mut() {
        if z.im.abs() <= IMAG_SNAP * scale {
            z.im = 0.0;
        }
    }
    let mut used = vec![false; p.len()];
    for i in 0..p.len() {
        if p[i].im <= 0.0 || used[i] {
            continue;
        }
        let mut best: Option<(usize, f64)> = None;
        for j in 0..p.len() {
            if j == i || used[j] || p[j].im >= 0.0 {
                continue;
            }
            let d = (p[i].re - p[j].re).hypot(p[i].im + p[j].im);
            let closer = match best {
                None => true,
                Some((_, bd)) => d < bd,
            };
            if closer {
                best = Some((j, d));
            }
        }
        if let Some((j, _)) = best {
            used[i] = true;
            used[j] = true;
            let re = 0.5 * (p[i].re + p[j].re);
            let im = 0.5 * (p[i].im - p[j].im);
            p[i] = Pole::new(re, im);
            p[j] = Pole::new(re, -im);
        }
    }
    p.sort_by(|x, y| x.re.total_cmp(&y.re).then(x.im.total_cmp(&y.im)));
    p
}

/// Parses a comma-separated pole list such as `"-2+3.464i, -2-3.464i, -40, -45"`.
///
/// Each item is `re`, `im i`, or `re ± im i`; `j` may be used instead of `i`,
/// spaces are ignored, `i` alone means `1i`, and exponents (`1e-3`) are
/// accepted. Errors name the offending item and its position.
pub fn parse_poles(text: &str) -> Result<Vec<Pole>, LinearError> {
    if text.trim().is_empty() {
        return Err(LinearError::NoPoles);
    }
    text.split(',')
        .enumerate()
        .map(|(index, item)| parse_pole(index, item))
        .collect()
}

fn parse_pole(index: usize, item: &str) -> Result<Pole, LinearError> {
    let err = |reason| LinearError::InvalidPole {
        index,
        item: item.trim().to_string(),
        reason,
    };
    let s: String = item.chars().filter(|c| !c.is_whitespace()).collect();
    if s.is_empty() {
        return Err(err("empty item"));
    }
    let (body, imaginary) = match s.strip_suffix(['i', 'j', 'I', 'J']) {
        Some(b) => (b, true),
        None => (s.as_str(), false),
    };
    // Split at the last sign that is neither leading nor part of an exponent.
    let bytes = body.as_bytes();
    let split = (1..bytes.len())
        .rev()
        .find(|&k| (bytes[k] == b'+' || bytes[k] == b'-') && !matches!(bytes[k - 1], b'e' | b'E'));
    let num = |t: &str| -> Result<f64, LinearError> {
        // Reject words that Rust's float parser accepts (inf, nan, infinity).
        if t.chars()
            .any(|c| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
        {
            return Err(err("not a number"));
        }
        let v: f64 = t.parse().map_err(|_| err("not a number"))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(err("not finite"))
        }
    };
    let imag = |t: &str| -> Result<f64, LinearError> {
        match t {
            "" | "+" => Ok(1.0),
            "-" => Ok(-1.0),
            _ => num(t),
        }
    };
    match (imaginary, split) {
        (false, _) => Ok(Pole::real(num(body)?)),
        (true, None) => Ok(Pole::new(0.0, imag(body)?)),
        (true, Some(k)) => Ok(Pole::new(num(&body[..k])?, imag(&body[k..])?)),
    }
}

/// Formats a pole as `re`, `re+imi` or `re-imi` (the syntax [`parse_poles`] reads).
pub fn format_pole(p: Pole) -> String {
    if p.im == 0.0 {
        format!("{}", p.re)
    } else {
        format!("{}{:+}i", p.re, p.im)
    }
}
