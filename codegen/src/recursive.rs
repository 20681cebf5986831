//! The forward dynamics of a chain by its separable structure
//! ([`plantc_derive::mechanics::SeparableMass`]): `O(n)` per call instead of
//! forming `M_theta` and factoring it (`O(n^2)` entries, `O(n^3)` LDL^T).
//!
//! In the angle coordinates `theta = S q`, with the generators `U_a`, `V_b`
//! (`R` each) and the diagonal `D_a` of `M_theta`:
//!
//! 1. `theta`, `theta'` from `q`, `q'`, each row of `S` from an earlier one
//!    plus the few coordinates where they differ (`theta_k = theta_(k-1) +
//!    q_k` for a chain);
//! 2. the Coriolis and centrifugal terms by sums over the links above and
//!    below (`c_a = D_a'/2 theta_a'^2 + U_a . sum_(b>a) V_b' theta_b'^2 + V_a
//!    . sum_(b<a) U_b' theta_b'^2`), the potential gradient, and the model's
//!    forces mapped to `theta` (`S^-T (Q0 + B u)`): `r = S^-T f - c - dV/dtheta`;
//! 3. `M_theta theta'' = r` by the Schur complements from the last link
//!    down, an `R x R` matrix `P` and an `R`-vector `z` (the articulated-body
//!    recursion): `h = P U_a + V_a`, `d = D_a + U_a . P U_a`,
//!    `rho = r_a - U_a . z`, then `P -= h h^T / d`, `z += h rho / d`; and
//!    from the first link up, `theta_a'' = (rho_a - h_a . t) / d_a`,
//!    `t += U_a theta_a''`;
//! 4. `q'' = S^-1 theta''`.
//!
//! Every product, sum and division is a value of the [`Graph`], so
//! parameter-only parts (the generators' coefficients, the diagonal, the
//! gravity factors) become coefficients computed once per parameter set.

use plantc_derive::mechanics::{AngleCoordinates, Equations, SeparableMass};
use plantc_derive::model::Model;
use plantc_derive::sym::{diff, Expr, Rational};

use crate::ir::{Graph, V};
use crate::plant::{combination, env};
use crate::Error;

/// `S x` row by row, each row from the earlier row it differs least from
/// (`theta_k = theta_j + sum_i (S[k][i] - S[j][i]) x_i`).
fn incremental(g: &mut Graph, s: &[Vec<Rational>], xs: &[V]) -> Vec<V> {
    let nnz = |r: &[Rational]| r.iter().filter(|c| !c.is_zero()).count();
    let mut out: Vec<V> = Vec::with_capacity(s.len());
    for k in 0..s.len() {
        let mut best: (usize, Option<usize>, Vec<Rational>) = (nnz(&s[k]), None, s[k].clone());
        for j in 0..k {
            let Some(d) = s[k]
                .iter()
                .zip(&s[j])
                .map(|(a, b)| a.checked_sub(*b))
                .collect::<Option<Vec<_>>>()
            else {
                continue;
            };
            if nnz(&d) < best.0 {
                best = (nnz(&d), Some(j), d);
            }
        }
        let delta = combination(g, &best.2, xs);
        out.push(match best.1 {
            Some(j) => g.add(out[j], delta),
            None => delta,
        });
    }
    out
}

/// `M^T x` for a rational matrix (column `k`: `sum_i m[i][k] x_i`).
fn transposed(g: &mut Graph, m: &[Vec<Rational>], xs: &[V]) -> Vec<V> {
    let n = m.len();
    (0..n)
        .map(|k| {
            let col: Vec<Rational> = (0..n).map(|i| m[i][k]).collect();
            combination(g, &col, xs)
        })
        .collect()
}

/// `x' = (q', q'')` at the state values `xs` by the separable recursion (see
/// the module docs).
#[allow(clippy::too_many_arguments)]
pub(crate) fn separable_dynamics(
    g: &mut Graph,
    model: &Model,
    eqs: &Equations,
    ac: &AngleCoordinates,
    sm: &SeparableMass,
    xs: &[V],
    us: &[V],
    ps: &[V],
) -> Result<Vec<V>, Error> {
    let n = ac.coords.len();
    let r = sm.factors.len();
    let mut e = env(g, model, xs, us, ps)?;
    let theta = incremental(g, &ac.s, &xs[..n]);
    let theta_d = incremental(g, &ac.s, &xs[n..2 * n]);
    for k in 0..n {
        e.bind(ac.coords[k].q, theta[k]);
        e.bind(ac.coords[k].qd, theta_d[k]);
    }
    let th: Vec<Expr> = ac.coords.iter().map(|c| Expr::symbol(c.q)).collect();
    let zero = g.konst(0.0);
    let half = g.konst(0.5);
    let mut u = vec![vec![zero; r]; n];
    let mut v = vec![vec![zero; r]; n];
    let mut du = vec![vec![zero; r]; n];
    let mut dv = vec![vec![zero; r]; n];
    let mut d = vec![zero; n];
    let mut dd = vec![zero; n];
    for a in 0..n {
        for k in 0..r {
            u[a][k] = g.expr(&mut e, sm.u(k, a, th[a]))?;
            v[a][k] = g.expr(&mut e, sm.v(k, a, th[a]))?;
            du[a][k] = g.expr(&mut e, sm.du(k, a, th[a]))?;
            dv[a][k] = g.expr(&mut e, sm.dv(k, a, th[a]))?;
        }
        d[a] = g.expr(&mut e, sm.diag[a])?;
        dd[a] = g.expr(&mut e, diff(sm.diag[a], ac.coords[a].q))?;
    }
    let w2: Vec<V> = theta_d.iter().map(|w| g.mul(*w, *w)).collect();
    // sum_(b > a) V_b' theta_b'^2 and sum_(b < a) U_b' theta_b'^2
    let mut above = vec![vec![zero; r]; n];
    for a in (0..n.saturating_sub(1)).rev() {
        for k in 0..r {
            let t = g.mul(dv[a + 1][k], w2[a + 1]);
            above[a][k] = g.add(above[a + 1][k], t);
        }
    }
    let mut below = vec![vec![zero; r]; n];
    for a in 1..n {
        for k in 0..r {
            let t = g.mul(du[a - 1][k], w2[a - 1]);
            below[a][k] = g.add(below[a - 1][k], t);
        }
    }
    // r = S^-T f - c - dV/dtheta
    let forces = applied_forces(eqs);
    let fq = forces
        .iter()
        .map(|f| g.expr(&mut e, *f))
        .collect::<Result<Vec<_>, _>>()?;
    let f_theta = transposed(g, &ac.s_inv, &fq);
    let mut rhs = Vec::with_capacity(n);
    for a in 0..n {
        let mut c = g.mul(dd[a], w2[a]);
        c = g.mul(half, c);
        for k in 0..r {
            let t1 = g.mul(u[a][k], above[a][k]);
            let t2 = g.mul(v[a][k], below[a][k]);
            c = g.add(c, t1);
            c = g.add(c, t2);
        }
        let grav = g.expr(&mut e, sm.potential_gradient[a])?;
        let x = g.sub(f_theta[a], c);
        rhs.push(g.sub(x, grav));
    }
    // Schur complements from the last link down
    let mut p = vec![vec![zero; r]; r];
    let mut z = vec![zero; r];
    let mut hs = vec![vec![zero; r]; n];
    let mut inv = vec![zero; n];
    let mut rho = vec![zero; n];
    let one = g.konst(1.0);
    for a in (0..n).rev() {
        let pu: Vec<V> = (0..r)
            .map(|i| {
                let mut acc = zero;
                for j in 0..r {
                    let t = g.mul(p[i][j], u[a][j]);
                    acc = g.add(acc, t);
                }
                acc
            })
            .collect();
        let h: Vec<V> = (0..r).map(|i| g.add(pu[i], v[a][i])).collect();
        let mut dh = d[a];
        let mut ro = rhs[a];
        for i in 0..r {
            let t = g.mul(u[a][i], pu[i]);
            dh = g.add(dh, t);
            let t = g.mul(u[a][i], z[i]);
            ro = g.sub(ro, t);
        }
        let iv = g.div(one, dh);
        let k: Vec<V> = h.iter().map(|hi| g.mul(*hi, iv)).collect();
        if a > 0 {
            for i in 0..r {
                for j in 0..=i {
                    let t = g.mul(k[i], h[j]);
                    let x = g.sub(p[i][j], t);
                    p[i][j] = x;
                    p[j][i] = x;
                }
                let t = g.mul(k[i], ro);
                z[i] = g.add(z[i], t);
            }
        }
        hs[a] = h;
        inv[a] = iv;
        rho[a] = ro;
    }
    // from the first link up
    let mut t = vec![zero; r];
    let mut acc = Vec::with_capacity(n);
    for a in 0..n {
        let mut x = rho[a];
        for i in 0..r {
            let y = g.mul(hs[a][i], t[i]);
            x = g.sub(x, y);
        }
        let x = g.mul(x, inv[a]);
        if a + 1 < n {
            for i in 0..r {
                let y = g.mul(u[a][i], x);
                t[i] = g.add(t[i], y);
            }
        }
        acc.push(x);
    }
    let qdd = incremental(g, &ac.s_inv, &acc);
    let mut out: Vec<V> = xs[n..2 * n].to_vec();
    out.extend(qdd);
    Ok(out)
}

/// `Q0 + B u` of each model coordinate.
fn applied_forces(eqs: &Equations) -> Vec<Expr> {
    (0..eqs.coords.len())
        .map(|i| {
            let bu: Expr = eqs
                .inputs
                .iter()
                .enumerate()
                .map(|(j, u)| eqs.input_matrix[i][j] * Expr::symbol(*u))
                .sum();
            eqs.forces[i] + bu
        })
        .collect()
}
