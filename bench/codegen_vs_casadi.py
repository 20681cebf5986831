"""Rotary-pendulum dynamics, feedback-linearizing law and RK4 step (h = 1 ms)
written in CasADi, exported as C, the same model as
models/rotary_pendulum.plant (gearbox dry friction -Fg1 sign(theta') included).

Two versions of each function:

* `cas_*`: the parameters and the gains are inputs (live), like plantc's
  generated `Plant` and controller, whose parameters can change at run time:
  the fair comparison (bench/codegen_vs_casadi.sh prints these ratios);
* `casc_*`: the thesis values compiled in as constants, so CasADi folds
  what they make vanish (Fg1 = 0 removes the sign term); shown for
  reference only, plantc never specialises its parameters.

Usage: python codegen_vs_casadi.py OUTDIR   -> OUTDIR/cas.c, OUTDIR/cas.h
"""
import os
import sys

import casadi as ca

out = sys.argv[1]
# parameter order of the wrapper's array (bench/codegen_vs_casadi_wrap.c)
names = ["m1", "L1", "l1", "J1", "b1", "m2", "l2", "J2", "b2", "g", "Kg", "kt", "km",
         "eta_m", "eta_g", "Rm", "Fg1", "wn", "zeta"]
# thesis set (models/rotary_pendulum.plant, set thesis: Fg1 = 0), gains wn = 4, zeta = 0.7
values = [0.257, 0.216, 0.0619, 9.98e-4, 0.0024, 0.127, 0.156, 0.0012, 0.0024, 9.81, 70.0,
          7.68e-3, 7.68e-3, 0.69, 0.9, 2.6, 0.0, 4.0, 0.7]

x = ca.SX.sym("x", 4)
u = ca.SX.sym("u", 1)
p = ca.SX.sym("p", len(names))
P = {n: p[i] for i, n in enumerate(names)}
th, al, thd, ald = x[0], x[1], x[2], x[3]
J0h = P["J1"] + P["m1"] * P["l1"] ** 2 + P["m2"] * P["L1"] ** 2
J2h = P["J2"] + P["m2"] * P["l2"] ** 2
c = P["m2"] * P["L1"] * P["l2"]
s, co = ca.sin(al), ca.cos(al)
tau = P["eta_g"] * P["Kg"] * P["eta_m"] * P["kt"] * (u[0] - P["Kg"] * P["km"] * thd) / P["Rm"]
M = ca.vertcat(ca.horzcat(J0h + J2h * s**2, -c * co), ca.horzcat(-c * co, J2h))
r = ca.vertcat(
    tau - P["b1"] * thd - P["Fg1"] * ca.sign(thd) - 2 * J2h * s * co * ald * thd - c * s * ald**2,
    -P["b2"] * ald + J2h * s * co * thd**2 + P["m2"] * P["g"] * P["l2"] * s,
)
acc = ca.solve(M, r)
xdot = ca.vertcat(thd, ald, acc)

# feedback linearization of alpha: alpha'' = fa(x) + ga(x) u
fa = ca.substitute(acc[1], u, ca.SX(0))
ga = ca.jacobian(acc[1], u)
v = -P["wn"] ** 2 * al - 2 * P["zeta"] * P["wn"] * ald
law = (v - fa) / ga

dyn = ca.Function("dyn_p", [x, u, p], [xdot])
h = 1e-3
k1 = dyn(x, u, p)
k2 = dyn(x + h / 2 * k1, u, p)
k3 = dyn(x + h / 2 * k2, u, p)
k4 = dyn(x + h * k3, u, p)
step = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

const = ca.DM(values)
fns = [
    ca.Function("cas_dynamics", [x, u, p], [xdot]),
    ca.Function("cas_fl_law", [x, p], [law]),
    ca.Function("cas_rk4", [x, u, p], [step]),
    ca.Function("casc_dynamics", [x, u], [ca.substitute(xdot, p, const)]),
    ca.Function("casc_fl_law", [x], [ca.substitute(law, p, const)]),
    ca.Function("casc_rk4", [x, u], [ca.substitute(step, p, const)]),
]
cg = ca.CodeGenerator("cas.c", {"with_header": True})
for f in fns:
    cg.add(f)
cwd = os.getcwd()
os.chdir(out)
cg.generate()
os.chdir(cwd)
print("casadi", ca.__version__, "->", os.path.join(out, "cas.c"))
