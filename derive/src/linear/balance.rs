//! Diagonal balancing of a state-space pair: `x = D z` with `D` a diagonal of
//! powers of two (exact), chosen so that the rows and columns of
//! `D^-1 A D` have comparable norms (Parlett-Reinsch, as LAPACK `gebal`).
//! A similarity: eigenvalues, controllability and the LQR problem are the
//! same, but tests on the balanced matrices see the system's own scales
//! instead of its units.

use nalgebra::DMatrix;

/// `D` (its diagonal) for `a`; `d[i] = 2^k`.
pub fn balancing_scales(a: &DMatrix<f64>) -> Vec<f64> {
    let n = a.nrows();
    let mut d = vec![1.0f64; n];
    let mut m = a.clone();
    for _ in 0..100 {
        let mut changed = false;
        for i in 0..n {
            let mut c = 0.0;
            let mut r = 0.0;
            for j in 0..n {
                if j != i {
                    c += m[(j, i)].abs();
                    r += m[(i, j)].abs();
                }
            }
            if c == 0.0 || r == 0.0 {
                continue;
            }
            let s = c + r;
            let mut f = 1.0;
            let (mut c2, mut r2) = (c, r);
            while c2 < r2 / 2.0 {
                c2 *= 2.0;
                r2 /= 2.0;
                f *= 2.0;
            }
            while c2 >= r2 * 2.0 {
                c2 /= 2.0;
                r2 *= 2.0;
                f /= 2.0;
            }
            if c2 + r2 < 0.95 * s {
                changed = true;
                d[i] *= f;
                for j in 0..n {
                    m[(j, i)] *= f;
                    m[(i, j)] /= f;
                }
            }
        }
        if !changed {
            break;
        }
    }
    d
}

/// `(D^-1 A D, D^-1 B)` with `D` from [`balancing_scales`], and `D`.
pub fn balance(a: &DMatrix<f64>, b: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>, Vec<f64>) {
    let d = balancing_scales(a);
    let ab = DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] * d[j] / d[i]);
    let bb = DMatrix::from_fn(b.nrows(), b.ncols(), |i, j| b[(i, j)] / d[i]);
    (ab, bb, d)
}
