"""Independent computation of the MIMO input-output analysis of
models/twip_yaw.plant (two inputs vl, vr): the reference numbers of
derive/tests/analysis_mimo.rs.

Everything is derived here from the physics as the model file states it
(kinetic and potential energy, generalised forces), with SymPy only: the
Euler-Lagrange equations, x' = f(x) + g(x) u with the accelerations solved by
M^-1 (LU), Lie derivatives by differentiation in the 6 states, the decoupling
matrix A(x) = [L_g L_f h_i] and b(x) = [L_f^2 h_i] at a few random states, and
the zero dynamics' eigenvalues at the upright equilibrium. The zero dynamics
are computed in a chart of their own (not plantc's eta): the manifold
{h = 0, L_f h = 0} is parametrised by the coordinate the outputs leave free
and its velocity, the closed loop x' = f + g u* with u* = -A^-1 b restricted to
it, and its Jacobian at 0 (eigenvalues do not depend on the chart).

Three output pairs: the model's declared (psi, phi); the forward position
x = R*theta with phi; the forward position of the body's centre of mass
xc = R*theta + L*sin(psi) with phi.

Run (a venv with SymPy, made on first use; SymPy is never a product dependency):

    bash -c '. bench/sympy_venv.sh; "$VENV/bin/python" bench/twip_yaw_decoupling_sympy.py'

Prints JSON (states, A, b, eigenvalues at 17 significant digits).
"""
import json
import random

import sympy as sp

R_ = sp.Rational
# parameter values of models/twip_yaw.plant, exact
m, R, M, W, Dp, H = R_("0.03"), R_("0.04"), R_("0.6"), R_("0.14"), R_("0.04"), R_("0.144")
Jm, Rm, Kb, Kt, fm, g = R_("1e-5"), R_("6.69"), R_("0.468"), R_("0.317"), R_("0.0022"), R_("9.81")

Jw = m * R**2 / 2
L = H / 2
Jpsi = M * L**2 / 3
Jphi = M * (W**2 + Dp**2) / 12
alpha_m = Kt / Rm
beta_m = Kt * Kb / Rm + fm

th, ps, ph, thd, psd, phd, vl, vr = sp.symbols("theta psi phi thetad psid phid vl vr")
q = [th, ps, ph]
qd = [thd, psd, phd]
X = q + qd
U = [vl, vr]

wl = thd - W / (2 * R) * phd - psd
wr = thd + W / (2 * R) * phd - psd
vbx = R * thd * sp.cos(ph) + L * sp.cos(ps) * sp.cos(ph) * psd - L * sp.sin(ps) * sp.sin(ph) * phd
vby = R * thd * sp.sin(ph) + L * sp.cos(ps) * sp.sin(ph) * psd + L * sp.sin(ps) * sp.cos(ph) * phd
vbz = -L * sp.sin(ps) * psd
T = (m * R**2 * thd**2 + m * W**2 / 4 * phd**2 + Jw * thd**2 + Jw * W**2 / (4 * R**2) * phd**2
     + R_(1, 2) * M * (vbx**2 + vby**2 + vbz**2) + R_(1, 2) * Jpsi * psd**2
     + R_(1, 2) * Jphi * phd**2 + R_(1, 2) * Jm * (wl**2 + wr**2))
V = M * g * L * sp.cos(ps)
Q = [
    alpha_m * (vl + vr) - beta_m * (wl + wr),
    -alpha_m * (vl + vr) + beta_m * (wl + wr),
    W / (2 * R) * (alpha_m * (vr - vl) - beta_m * (wr - wl)),
]

# Euler-Lagrange: M qdd + bias = Q
Lag = T - V
p = [sp.diff(T, v) for v in qd]
Mm = sp.Matrix(3, 3, lambda i, j: sp.expand(sp.diff(p[i], qd[j])))
bias = [sum(sp.diff(p[i], q[k]) * qd[k] for k in range(3)) - sp.diff(Lag, q[i]) for i in range(3)]
rhs = sp.Matrix([Q[i] - bias[i] for i in range(3)])
qdd = Mm.LUsolve(rhs)
f = list(qd) + [e.subs({vl: 0, vr: 0}) for e in qdd]
G = [[0, 0, 0] + [sp.diff(e, u) for e in qdd] for u in U]  # columns g_j


def lie(h, field):
    return sum(sp.diff(h, x) * v for x, v in zip(X, field))


def chain(h):
    """(L_g h row, L_f h, L_g L_f h row, L_f^2 h)."""
    lgh = [sp.simplify(lie(h, gj)) for gj in G]
    lfh = lie(h, f)
    lglfh = [lie(lfh, gj) for gj in G]
    lf2h = lie(lfh, f)
    return lgh, lfh, lglfh, lf2h


PAIRS = {
    "psi,phi": (ps, ph),
    "x,phi": (R * th, ph),
    "xc,phi": (R * th + L * sp.sin(ps), ph),
}

rng = random.Random(30)
STATES = [[round(rng.uniform(-1.2, 1.2), 6) for _ in range(6)] for _ in range(3)]
DIGITS = 30


def at(e, state):
    return sp.N(e.subs({x: R_(str(v)) for x, v in zip(X, state)}), DIGITS)


def num(v):
    return float(f"{float(v):.17g}")


out = {"sympy": sp.__version__, "states": STATES, "pairs": {}}
for name, hs in PAIRS.items():
    chains = [chain(h) for h in hs]
    for lgh, *_ in chains:
        assert all(e == 0 for e in lgh), "L_g h must vanish: relative degree 2 expected"
    A = sp.Matrix([c[2] for c in chains])
    b = sp.Matrix([c[3] for c in chains])
    rec = {"A": [], "b": []}
    for s in STATES:
        rec["A"].append([[num(at(A[i, j], s)) for j in range(2)] for i in range(2)])
        rec["b"].append([num(at(b[i], s)) for i in range(2)])
    # zero dynamics in the chart (z, z') of the coordinate the outputs leave free
    z, zd = sp.symbols("z zd")
    if name == "psi,phi":
        onz = {th: z, thd: zd, ps: 0, psd: 0, ph: 0, phd: 0}
        free = 3  # index of theta' in x
    elif name == "x,phi":
        onz = {th: 0, thd: 0, ps: z, psd: zd, ph: 0, phd: 0}
        free = 4
    else:
        onz = {th: -L * sp.sin(z) / R, thd: -L * sp.cos(z) * zd / R, ps: z, psd: zd, ph: 0, phd: 0}
        free = 4
    ustar = -A.LUsolve(b)
    xdot = [f[k] + G[0][k] * ustar[0] + G[1][k] * ustar[1] for k in range(6)]
    zdd = xdot[free].subs(onz)
    zero = {z: 0, zd: 0}
    a0 = sp.nsimplify(sp.diff(zdd, z).subs(zero))
    a1 = sp.nsimplify(sp.diff(zdd, zd).subs(zero))
    jac = sp.Matrix([[0, 1], [a0, a1]])
    # [[0, 1], [a0, a1]]: lambda^2 - a1 lambda - a0 = 0, in closed form
    disc = sp.sqrt(a1**2 + 4 * a0)
    eig = sorted((complex(sp.N(e, DIGITS)) for e in [(a1 - disc) / 2, (a1 + disc) / 2]),
                 key=lambda c: (c.real, c.imag))
    rec["zero_dynamics_jacobian"] = [[num(jac[i, j]) for j in range(2)] for i in range(2)]
    rec["eigenvalues"] = [[num(e.real), num(e.imag)] for e in eig]
    # equilibrium residual: z'' at z = z' = 0
    rec["residual"] = num(sp.N(zdd.subs(zero), DIGITS))
    out["pairs"][name] = rec
print(json.dumps(out, indent=1))
