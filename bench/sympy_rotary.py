"""The rotary pendulum written for SymPy's LagrangesMethod (shared by the
bench scripts; the same model as models/rotary_pendulum.plant).

`build()` creates the symbols, T, V and generalised forces (applied as
torques on the arm and pendulum frames) and forms the Euler-Lagrange
equations; the caller times it as SymPy's counterpart of parsing and deriving.
"""
from types import SimpleNamespace

import sympy as sp
from sympy.physics.mechanics import LagrangesMethod, ReferenceFrame, dynamicsymbols


def build():
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
    # The `quanser_manual` parameter set (thesis Eq. 3-4).
    values = {m1: 0.257, L1: 0.216, l1: 0.0619, m2: 0.127, L2: 0.337, l2: 0.1685, J2: 0.0012,
              b1: 0.0024, b2: 0.0024, g: 9.81, Kg: 70, kt: 7.68e-3, km: 7.68e-3, eta_m: 1, eta_g: 1,
              Rm: 2.6, Fg1: 0}
    values[J1] = 9.98e-4 - 0.257 * 0.0619**2
    return SimpleNamespace(th=th, al=al, thd=thd, ald=ald, Vm=Vm, lm=lm, values=values)
