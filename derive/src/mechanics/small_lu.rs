//! In-place LU factorisation with partial pivoting for the small dense systems
//! of mechanics (`M a = r`, n <= ~6), without allocation. Shared by the
//! numeric dynamics here and by identification's sensitivity integrator, which
//! solves several right-hand sides with one factorisation.

/// Factor the row-major `n x n` matrix `a` in place (`L` below the diagonal
/// with unit diagonal, `U` on and above it); `piv` receives the row order.
/// Returns false if a pivot is at most `tiny` or not finite.
#[inline]
pub fn lu_factor(a: &mut [f64], n: usize, piv: &mut [usize], tiny: f64) -> bool {
    for (i, p) in piv.iter_mut().enumerate().take(n) {
        *p = i;
    }
    for k in 0..n {
        let mut p = k;
        let mut best = a[k * n + k].abs();
        for i in k + 1..n {
            let v = a[i * n + k].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        if best <= tiny || !best.is_finite() {
            return false;
        }
        if p != k {
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
            piv.swap(k, p);
        }
        let d = a[k * n + k];
        for i in k + 1..n {
            let l = a[i * n + k] / d;
            a[i * n + k] = l;
            if l != 0.0 {
                for j in k + 1..n {
                    a[i * n + j] -= l * a[k * n + j];
                }
            }
        }
    }
    true
}

/// Solve `A x = b` with the factors of [`lu_factor`]; `b` is overwritten by
/// `x`; `tmp` (length `n`) is scratch.
#[inline]
pub fn lu_solve(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64], tmp: &mut [f64]) {
    for i in 0..n {
        tmp[i] = b[piv[i]];
    }
    for i in 0..n {
        let mut s = tmp[i];
        for j in 0..i {
            s -= lu[i * n + j] * tmp[j];
        }
        tmp[i] = s;
    }
    for i in (0..n).rev() {
        let mut s = tmp[i];
        for j in i + 1..n {
            s -= lu[i * n + j] * tmp[j];
        }
        tmp[i] = s / lu[i * n + i];
    }
    b[..n].copy_from_slice(&tmp[..n]);
}

/// The inverse of the row-major `n x n` matrix `a` into `inv`: by cofactors
/// for `n <= 3` (the mass matrices of most rigs, where the general
/// factorisation costs more than the arithmetic), else by [`lu_factor`] and
/// one [`lu_solve`] per column, with `lu` (`n x n`), `piv` and `tmp`, `col`
/// (length `n`) as scratch. Returns false when the matrix is singular to
/// working precision (a zero or non-finite determinant for `n <= 3`, a
/// pivot at most `tiny` otherwise).
#[inline]
pub fn invert(
    a: &[f64],
    n: usize,
    inv: &mut [f64],
    (lu, piv, tmp, col): (&mut [f64], &mut [usize], &mut [f64], &mut [f64]),
    tiny: f64,
) -> bool {
    match n {
        1 => {
            let d = a[0];
            inv[0] = 1.0 / d;
            d.abs() > tiny && d.is_finite()
        }
        2 => {
            let d = a[0] * a[3] - a[1] * a[2];
            if !(d.is_finite() && d != 0.0) {
                return false;
            }
            let r = 1.0 / d;
            inv[0] = a[3] * r;
            inv[1] = -a[1] * r;
            inv[2] = -a[2] * r;
            inv[3] = a[0] * r;
            true
        }
        3 => {
            let c00 = a[4] * a[8] - a[5] * a[7];
            let c01 = a[5] * a[6] - a[3] * a[8];
            let c02 = a[3] * a[7] - a[4] * a[6];
            let d = a[0] * c00 + a[1] * c01 + a[2] * c02;
            if !(d.is_finite() && d != 0.0) {
                return false;
            }
            let r = 1.0 / d;
            inv[0] = c00 * r;
            inv[1] = (a[2] * a[7] - a[1] * a[8]) * r;
            inv[2] = (a[1] * a[5] - a[2] * a[4]) * r;
            inv[3] = c01 * r;
            inv[4] = (a[0] * a[8] - a[2] * a[6]) * r;
            inv[5] = (a[2] * a[3] - a[0] * a[5]) * r;
            inv[6] = c02 * r;
            inv[7] = (a[1] * a[6] - a[0] * a[7]) * r;
            inv[8] = (a[0] * a[4] - a[1] * a[3]) * r;
            true
        }
        _ => {
            lu[..n * n].copy_from_slice(&a[..n * n]);
            if !lu_factor(lu, n, piv, tiny) {
                return false;
            }
            for c in 0..n {
                col[..n].iter_mut().for_each(|v| *v = 0.0);
                col[c] = 1.0;
                lu_solve(lu, n, piv, col, tmp);
                for i in 0..n {
                    inv[i * n + c] = col[i];
                }
            }
            true
        }
    }
}

#[cfg(test)]
mod invert_tests {
    use super::invert;

    /// `a inv = I` to rounding, for the cofactor sizes and the LU path,
    /// on well-conditioned matrices made from a fixed pseudo-random draw.
    #[test]
    fn inverse_times_matrix_is_identity() {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        for n in 1..=5 {
            let mut a = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] = next() + if i == j { 2.0 } else { 0.0 };
                }
            }
            let mut inv = vec![0.0; n * n];
            let (mut lu, mut piv, mut tmp, mut col) =
                (vec![0.0; n * n], vec![0; n], vec![0.0; n], vec![0.0; n]);
            assert!(invert(
                &a,
                n,
                &mut inv,
                (&mut lu, &mut piv, &mut tmp, &mut col),
                0.0
            ));
            for i in 0..n {
                for j in 0..n {
                    let s: f64 = (0..n).map(|k| a[i * n + k] * inv[k * n + j]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((s - want).abs() < 1e-13, "n = {n}: ({i}, {j}) = {s}");
                }
            }
        }
        let singular = [1.0, 2.0, 2.0, 4.0];
        let mut inv = [0.0; 4];
        let (mut lu, mut piv, mut tmp, mut col) = ([0.0; 4], [0; 2], [0.0; 2], [0.0; 2]);
        assert!(!invert(
            &singular,
            2,
            &mut inv,
            (&mut lu, &mut piv, &mut tmp, &mut col),
            0.0
        ));
    }
}
