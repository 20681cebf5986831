"""SymPy's LagrangesMethod pipeline for the rotary pendulum, timed.

Builds the model (the step that corresponds to parsing a .plant file), forms
the Euler-Lagrange equations with generalised forces applied as torques on the
arm and pendulum frames, and linearizes about upright with the `quanser_manual`
parameter set. Prints JSON: {"seconds": ..., "A21": ..., "sympy": version}.
"""
import json
import time

import sympy as sp

from sympy_rotary import build

t0 = time.perf_counter()
r = build()
th, al, thd, ald, Vm, lm, values = r.th, r.al, r.thd, r.ald, r.Vm, r.lm, r.values
op = {th: 0, al: 0, thd: 0, ald: 0, Vm: 0}
Amat, Bmat, _ = lm.linearize(q_ind=[th, al], qd_ind=[thd, ald], A_and_B=True, op_point=op)
Anum = Amat.subs(values)
a21 = float(Anum[2, 1])
seconds = time.perf_counter() - t0
print(json.dumps({"seconds": seconds, "A21": a21, "sympy": sp.__version__}))
