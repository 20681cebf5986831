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
from sympy.physics.mechanics import LagrangesMethod, ReferenceFrame, dynamicsymbols

t0 = time.perf_counter()
th, al = dynamicsymbols("theta alpha")
thd, ald = dynamicsymbols("theta alpha", 1)
Vm = dynamicsymbols("Vm")
m1, L1, l1, J1, b1, m2, L2, l2, J2, b2, g = sp.symbols("m1 L1 l1 J1 b1 m2 L2 l2 J2 b2 g")
Kg, kt, km, eta_m, eta_g, Rm, Fg1 = sp.symbols("Kg kt km eta_m eta_g Rm Fg1")
J0h = J1 + m1 * l1**2 + m2 * L1**2
J2h = J2 + m2 * l2**2
c = m2 * L1 * l2
T = sp.Rational(1, 2) * (J0h + J2h * sp.sin(al) ** 2) * thd**2 - c * sp.cos(al) * thd * ald + sp.Rational(1, 2) * J2h * ald**2
V = m2 * g * l2 * sp.cos(al)
tau = eta_g * Kg * eta_m * kt * (Vm - Kg * km * thd) / Rm
N = ReferenceFrame("N")
A = N.orientnew("A", "Axis", [th, N.z])
B = A.orientnew("B", "Axis", [al, A.x])
forces = [(A, (tau - b1 * thd - Fg1 * sp.sign(thd)) * N.z), (B, -b2 * ald * A.x)]
lm = LagrangesMethod(T - V, [th, al], forcelist=forces, frame=N)
lm.form_lagranges_equations()
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
