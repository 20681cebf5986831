"""Rotary-pendulum dynamics, feedback-linearizing law and RK4 step (h = 1 ms)
written in CasADi (thesis parameter values as constants), exported as C.

Usage: python codegen_vs_casadi.py OUTDIR   -> OUTDIR/cas.c, OUTDIR/cas.h
"""
import os
import sys

import casadi as ca

out = sys.argv[1]
# thesis set (models/rotary_pendulum.plant, Fg1 = 0)
m1, L1, l1, J1, b1 = 0.257, 0.216, 0.0619, 9.98e-4, 0.0024
m2, L2, l2, J2, b2 = 0.127, 0.337, 0.156, 0.0012, 0.0024
g, Kg, kt, km, eta_m, eta_g, Rm = 9.81, 70.0, 7.68e-3, 7.68e-3, 0.69, 0.9, 2.6
J0h = J1 + m1 * l1**2 + m2 * L1**2
J2h = J2 + m2 * l2**2
c = m2 * L1 * l2
wn, zeta = 4.0, 0.7

x = ca.SX.sym("x", 4)
u = ca.SX.sym("u", 1)
th, al, thd, ald = x[0], x[1], x[2], x[3]
s, co = ca.sin(al), ca.cos(al)
tau = eta_g * Kg * eta_m * kt * (u[0] - Kg * km * thd) / Rm
M = ca.vertcat(ca.horzcat(J0h + J2h * s**2, -c * co), ca.horzcat(-c * co, J2h))
r = ca.vertcat(
    tau - b1 * thd - 2 * J2h * s * co * ald * thd - c * s * ald**2,
    -b2 * ald + J2h * s * co * thd**2 + m2 * g * l2 * s,
)
acc = ca.solve(M, r)
xdot = ca.vertcat(thd, ald, acc)
dyn = ca.Function("cas_dynamics", [x, u], [xdot])

# feedback linearization of alpha: alpha'' = fa(x) + ga(x) u
fa = ca.substitute(acc[1], u, ca.SX(0))
ga = ca.jacobian(acc[1], u)
v = -wn**2 * al - 2 * zeta * wn * ald
law = ca.Function("cas_fl_law", [x], [(v - fa) / ga])

h = 1e-3
k1 = dyn(x, u)
k2 = dyn(x + h / 2 * k1, u)
k3 = dyn(x + h / 2 * k2, u)
k4 = dyn(x + h * k3, u)
rk4 = ca.Function("cas_rk4", [x, u], [x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])

cg = ca.CodeGenerator("cas.c", {"with_header": True})
for f in (dyn, law, rk4):
    cg.add(f)
cwd = os.getcwd()
os.chdir(out)
cg.generate()
os.chdir(cwd)
print("casadi", ca.__version__, "->", os.path.join(out, "cas.c"))
