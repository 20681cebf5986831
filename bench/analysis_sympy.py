"""SymPy's share of the analysis pipeline for the rotary pendulum, timed.

Steps SymPy can do directly: build the model, LagrangesMethod EOM, solve for
the accelerations (mass-matrix LU solve), and Lie derivatives of h = alpha
(L_f h, L_g h, L_f^2 h, L_g L_f h) by differentiation. SymPy has no normal form
or zero-dynamics routine, so those steps are plantc-only. A second timing adds
`sp.simplify` of L_g L_f h (plantc's Lie derivatives come out in canonical,
simplified form). Prints JSON.
"""
import json
import time

import sympy as sp

from sympy_rotary import build

t0 = time.perf_counter()
r = build()
th, al, thd, ald, Vm, lm = r.th, r.al, r.thd, r.ald, r.Vm, r.lm
t_eom = time.perf_counter()
# Accelerations: M qdd = forcing.
acc = lm.mass_matrix.LUsolve(lm.forcing)
t_acc = time.perf_counter()
# Plain symbols for the state and the input.
x1, x2, x3, x4, u = sp.symbols("theta alpha thetad alphad Vm_")
plain = {thd: x3, ald: x4, th: x1, al: x2, Vm: u}
a = [sp.sympify(e).subs(plain) for e in acc]
f = [x3, x4] + [e.subs(u, 0) for e in a]
gv = [0, 0] + [sp.diff(e, u) for e in a]
X = [x1, x2, x3, x4]


def lie(h, field):
    return sum(sp.diff(h, xi) * fi for xi, fi in zip(X, field))


h = x2
Lfh = lie(h, f)
Lgh = sp.simplify(lie(h, gv))
Lf2h = lie(Lfh, f)
LgLfh = lie(Lfh, gv)
t_lie = time.perf_counter()
LgLfh_s = sp.simplify(LgLfh)
t_simp = time.perf_counter()
print(json.dumps({
    "eom_s": t_eom - t0,
    "accelerations_s": t_acc - t_eom,
    "lie_s": t_lie - t_acc,
    "shared_s": t_lie - t0,
    "simplify_LgLfh_s": t_simp - t_lie,
    "Lgh_is_zero": bool(Lgh == 0),
    "sympy": sp.__version__,
}))
