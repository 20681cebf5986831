"""Whose rounding is the difference between plantc, MuJoCo and Pinocchio on the
n-link chain? Each implementation's accelerations (the dump of
bench/chain_harness.c with CHAIN_DUMP=FILE, at its random states) against a
reference computed here in 40-digit arithmetic (mpmath), from the physics of
plantc_derive::model::n_link_chain_source(n) written out independently:

  absolute angles theta_a = q1 + ... + qa, rates w_a; link k's centre of mass
  at sum_{a<k} L_a (sin, cos)(theta_a) + c_k (sin, cos)(theta_k);
  T = sum_k m_k |v_k|^2 / 2 + J_k w_k^2 / 2, V = g sum_k m_k y_k;
  in the angles: sum_b C_ab cos(theta_a - theta_b) theta_b''
               + sum_b C_ab sin(theta_a - theta_b) w_b^2
               - g G_a sin(theta_a) = (S^-T Q)_a,
  C_ab = sum_k m_k l_ka l_kb + J_a [a = b], G_a = sum_k m_k l_ka
  (l_ka = L_a for a < k, c_k for a = k, 0 beyond), theta = S q with S lower
  triangular ones, Q = (tau - b q1', -b q2', ...).
  So S^T M_theta S q'' = Q - S^T (Coriolis + gravity), solved by LU in
  40 digits.

The parameters are the doubles every implementation is given (m = 0.1,
L = 0.2, c = 0.1, J = 3.3e-4, b = 1e-4, g = 9.81, as binary64 values), and
the states are the dumped doubles, so the reference is the exact answer to
the question all three were asked (to about 1e-35). Also printed: the
condition number of M(q) (numpy, 2-norm) at the states, max and median, which
bounds how much of the input's rounding any method that forms and factors M
can lose.

    python bench/chain_precision.py DUMP [N_STATES]    (mpmath and numpy)

Prints, per implementation: max and median over the states of
||a - a_ref||_inf / ||a_ref||_inf (the harness's measure).
"""
import sys

import mpmath as mp
import numpy as np

mp.mp.dps = 40
M_, L_, C_, J_, B_, G_ = 0.1, 0.2, 0.1, 3.3e-4, 1e-4, 9.81


def read(path):
    states, accs = [], []
    for line in open(path):
        name, *vals = line.split()
        if name == "state":
            states.append([float(v) for v in vals])
            accs.append({})
        else:
            accs[-1][name] = [float(v) for v in vals]
    return states, accs


def reference(x, u, n):
    """q'' in 40 digits, and M(q) in doubles (for its condition number)."""
    mpf = mp.mpf
    m, L, c, J, b, g = (mpf(v) for v in (M_, L_, C_, J_, B_, G_))
    q = [mpf(v) for v in x[:n]]
    qd = [mpf(v) for v in x[n:]]
    th, w = [], []
    s, sd = mpf(0), mpf(0)
    for a in range(n):
        s += q[a]
        sd += qd[a]
        th.append(s)
        w.append(sd)
    # l_ka summed: C_ab = sum_k m l_ka l_kb (+ J), G_a = sum_k m l_ka
    # links k > max(a, b) see L_a L_b, link k = max(a, b) sees L_min c
    def lk(k, a):
        return L if a < k else (c if a == k else mpf(0))

    Cm = mp.matrix(n, n)
    G = [mpf(0)] * n
    for a in range(n):
        G[a] = m * c + m * L * (n - 1 - a)
        for bb in range(a, n):
            top = max(a, bb)
            v = m * lk(top, a) * lk(top, bb) + m * L * L * (n - 1 - top)
            if a == bb:
                v += J
            Cm[a, bb] = v
            Cm[bb, a] = v
    Mth = mp.matrix(n, n)
    rhs_th = [mpf(0)] * n
    for a in range(n):
        acc = mpf(0)
        for bb in range(n):
            d = th[a] - th[bb]
            Mth[a, bb] = Cm[a, bb] * mp.cos(d)
            acc += Cm[a, bb] * mp.sin(d) * w[bb] ** 2
        rhs_th[a] = acc - g * G[a] * mp.sin(th[a])
    # q-space: M = S^T Mth S (S lower triangular ones), rhs = Q - S^T rhs_th
    # (S^T v)_i = sum_{a >= i} v_a; (Mth S)_{a j} = sum_{bb >= j} Mth[a, bb]
    MS = mp.matrix(n, n)
    for a in range(n):
        run = mpf(0)
        for j in range(n - 1, -1, -1):
            run += Mth[a, j]
            MS[a, j] = run
    Mq = mp.matrix(n, n)
    for j in range(n):
        run = mpf(0)
        for i in range(n - 1, -1, -1):
            run += MS[i, j]
            Mq[i, j] = run
    r = mp.matrix(n, 1)
    run = mpf(0)
    for i in range(n - 1, -1, -1):
        run += rhs_th[i]
        r[i] = -b * qd[i] - run
    r[0] += mpf(u)
    qdd = mp.lu_solve(Mq, r)
    mq = np.array([[float(Mq[i, j]) for j in range(n)] for i in range(n)])
    return [qdd[i] for i in range(n)], mq


def main():
    states, accs = read(sys.argv[1])
    if len(sys.argv) > 2:
        k = int(sys.argv[2])
        states, accs = states[:k], accs[:k]
    n = (len(states[0]) - 1) // 2
    names = list(accs[0].keys())
    errs = {k: [] for k in names}
    conds = []
    for x, a in zip(states, accs):
        ref, mq = reference(x[: 2 * n], x[2 * n], n)
        scale = max(abs(v) for v in ref)
        for k in names:
            d = max(abs(mp.mpf(a[k][i]) - ref[i]) for i in range(n))
            errs[k].append(float(d / scale))
        conds.append(np.linalg.cond(mq))
    print(f"n = {n}, {len(states)} states: relative difference to the 40-digit reference")
    for k in names:
        e = sorted(errs[k])
        print(f"  {k:>10}: max {e[-1]:.2e}, median {e[len(e) // 2]:.2e}")
    c = sorted(conds)
    print(f"  cond(M(q)): max {c[-1]:.2e}, median {c[len(c) // 2]:.2e} "
          f"(times eps = 1.1e-16: {c[-1] * 1.1e-16:.1e}, {c[len(c) // 2] * 1.1e-16:.1e})")


if __name__ == "__main__":
    main()
