//! In-place LU factorisation with partial pivoting for the small dense systems
//! of mechanics (`M a = r`, n <= ~6), without allocation. Shared by the
//! numeric dynamics here and by identification's sensitivity integrator, which
//! solves several right-hand sides with one factorisation.

/// Factor the row-major `n x n` matrix `a` in place (`L` below the diagonal
/// with unit diagonal, `U` on and above it); `piv` receives the row order.
/// Returns false if a pivot is at most `tiny` or not finite.
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
