"""Peers of the n-link chain benchmark (bench/chain_scaling.sh): the same
planar chain as `plantc_derive::model::n_link_chain_source(n)` (relative joint
angles, link i: m = 0.1 kg, L = 0.2 m, centre of mass c = 0.1 m, inertia
J = 3.3e-4 kg m^2, joint friction b = 1e-4 N m s/rad, g = 9.81, torque at
joint 1), built three ways:

* SymPy: Euler-Lagrange by hessian/jacobian (no simplify), then `cse` and C
  code for M and F (`M q'' = F`), solved in C by an unrolled-loop Cholesky;
* CasADi: the same Lagrangian in SX, `solve(M, F)` (symbolic), C code;
* MuJoCo (if importable): an MJCF model of the chain (hinge joints, inertial
  frames, joint damping), called through its C API by the harness.

Usage: python chain_peers.py OUTDIR N [--no-sympy] [--no-casadi]
Writes OUTDIR/sympy_chain.c, OUTDIR/cas_chain.c (+ .h), OUTDIR/chain.xml and
prints one JSON line with the times (s) and peak memory (KB) of each stage.
"""
import json
import os
import resource
import sys
import time

out, n = sys.argv[1], int(sys.argv[2])
use_sympy = "--no-sympy" not in sys.argv
use_casadi = "--no-casadi" not in sys.argv
m, L, c, J, b, g = 0.1, 0.2, 0.1, 3.3e-4, 1e-4, 9.81
res = {"n": n}


def peak_kb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def lagrangian(cos, sin, q, qd):
    """T, V of the chain for symbolic q, qd (lists) and the cos/sin of a backend."""
    p, w = [], []
    for i in range(n):
        p.append(q[i] if i == 0 else p[-1] + q[i])
        w.append(qd[i] if i == 0 else w[-1] + qd[i])
    T, V = 0, 0
    for i in range(n):
        vx = sum(L * cos(p[k]) * w[k] for k in range(i)) + c * cos(p[i]) * w[i]
        vy = sum(L * sin(p[k]) * w[k] for k in range(i)) + c * sin(p[i]) * w[i]
        y = sum(L * cos(p[k]) for k in range(i)) + c * cos(p[i])
        T = T + 0.5 * m * (vx**2 + vy**2) + 0.5 * J * w[i] ** 2
        V = V + m * g * y
    return T, V


# ---------------------------------------------------------------- SymPy
if use_sympy:
    import sympy as sp

    t0 = time.perf_counter()
    q = sp.symbols(f"q0:{n}")
    qd = sp.symbols(f"qd0:{n}")
    u = sp.Symbol("u")
    T, V = lagrangian(sp.cos, sp.sin, q, qd)
    Lg = T - V
    dLdqd = [sp.diff(Lg, v) for v in qd]
    M = sp.Matrix(n, n, lambda i, j: sp.diff(dLdqd[i], qd[j]))
    Q = [(u if i == 0 else 0) - b * qd[i] for i in range(n)]
    F = sp.Matrix(
        [Q[i] + sp.diff(Lg, q[i]) - sum(sp.diff(dLdqd[i], q[k]) * qd[k] for k in range(n)) for i in range(n)]
    )
    res["sympy_derive_s"] = time.perf_counter() - t0
    res["sympy"] = sp.__version__
    t0 = time.perf_counter()
    exprs = [M[i, j] for i in range(n) for j in range(i + 1)] + list(F)
    reps, red = sp.cse(exprs)
    lines = [f"#include <math.h>\n#define N {n}\n", "void sympy_chain(const double *x, const double *uu, double *out) {"]
    for i in range(n):
        lines.append(f"  const double q{i} = x[{i}], qd{i} = x[{n + i}];")
    lines.append("  const double u = uu[0];")
    for s, e in reps:
        lines.append(f"  const double {s} = {sp.ccode(e)};")
    lines.append("  double A[N][N], r[N];")
    k = 0
    for i in range(n):
        for j in range(i + 1):
            lines.append(f"  A[{i}][{j}] = {sp.ccode(red[k])};")
            k += 1
    for i in range(n):
        lines.append(f"  r[{i}] = {sp.ccode(red[k])};")
        k += 1
    lines.append(
        """  /* Cholesky A = L L^T in the lower triangle, then two triangular solves */
  for (int j = 0; j < N; j++) {
    double d = A[j][j];
    for (int k = 0; k < j; k++) d -= A[j][k] * A[j][k];
    d = sqrt(d);
    A[j][j] = d;
    for (int i = j + 1; i < N; i++) {
      double s = A[i][j];
      for (int k = 0; k < j; k++) s -= A[i][k] * A[j][k];
      A[i][j] = s / d;
    }
  }
  for (int i = 0; i < N; i++) {
    double s = r[i];
    for (int k = 0; k < i; k++) s -= A[i][k] * r[k];
    r[i] = s / A[i][i];
  }
  for (int i = N - 1; i >= 0; i--) {
    double s = r[i];
    for (int k = i + 1; k < N; k++) s -= A[k][i] * r[k];
    r[i] = s / A[i][i];
  }
  for (int i = 0; i < N; i++) { out[i] = x[N + i]; out[N + i] = r[i]; }
}"""
    )
    with open(os.path.join(out, "sympy_chain.c"), "w") as f:
        f.write("\n".join(lines) + "\n")
    res["sympy_codegen_s"] = time.perf_counter() - t0
    res["sympy_peak_kb"] = peak_kb()

# ---------------------------------------------------------------- CasADi
if use_casadi:
    import casadi as ca

    t0 = time.perf_counter()
    x = ca.SX.sym("x", 2 * n)
    uu = ca.SX.sym("u", 1)
    q = [x[i] for i in range(n)]
    qd = [x[n + i] for i in range(n)]
    T, V = lagrangian(ca.cos, ca.sin, q, qd)
    Lg = T - V
    qv, qdv = x[:n], x[n:]
    dLdqd = ca.gradient(Lg, qdv)
    M = ca.jacobian(dLdqd, qdv)
    Q = ca.vertcat(*[(uu[0] if i == 0 else 0) - b * qd[i] for i in range(n)])
    F = Q + ca.gradient(Lg, qv) - ca.mtimes(ca.jacobian(dLdqd, qv), qdv)
    acc = ca.solve(M, F)
    dyn = ca.Function("cas_chain_f", [x, uu], [ca.vertcat(qdv, acc)])
    res["casadi_derive_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    cwd = os.getcwd()
    os.chdir(out)
    cg = ca.CodeGenerator("cas_chain.c", {"with_header": True})
    cg.add(dyn)
    cg.generate()
    os.chdir(cwd)
    with open(os.path.join(out, "cas_wrap.c"), "w") as f:
        f.write(
            '#include "cas_chain.h"\nstatic casadi_int iw[4096];\nstatic casadi_real w[1 << 20];\n'
            "void cas_chain(const double *x, const double *u, double *out) {\n"
            "  const casadi_real *arg[2] = {x, u};\n  casadi_real *res[1] = {out};\n"
            "  cas_chain_f(arg, res, iw, w, 0);\n}\n"
        )
    res["casadi_codegen_s"] = time.perf_counter() - t0
    res["casadi"] = ca.__version__

# ---------------------------------------------------------------- MuJoCo
try:
    import mujoco

    body = ""
    for i in reversed(range(n)):
        inner = body
        pos = "0 0 0" if i == 0 else f"0 0 {L}"
        body = (
            f'<body name="l{i}" pos="{pos}">'
            f'<joint name="j{i}" type="hinge" axis="0 1 0" damping="{b}"/>'
            f'<inertial pos="0 0 {c}" mass="{m}" diaginertia="{J} {J} {J}"/>'
            f"{inner}</body>"
        )
    xml = (
        '<mujoco model="chain"><option gravity="0 0 -9.81" timestep="0.001">'
        '<flag contact="disable" energy="disable"/></option>'
        f"<worldbody>{body}</worldbody>"
        '<actuator><motor joint="j0" gear="1"/></actuator></mujoco>'
    )
    with open(os.path.join(out, "chain.xml"), "w") as f:
        f.write(xml)
    mujoco.MjModel.from_xml_string(xml)
    res["mujoco"] = mujoco.__version__
except Exception as e:  # not installed or not loadable
    res["mujoco_error"] = str(e)

try:
    import pinocchio  # noqa: F401

    res["pinocchio"] = pinocchio.__version__
except Exception as e:
    res["pinocchio_error"] = str(e)

print(json.dumps(res))
