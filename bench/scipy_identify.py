"""The scipy peer of `plantc identify` on one rotary-pendulum case.

Our own implementation, written for bench/identify_vs_scipy.sh, of the
pipeline ../shared/reference/identification-notes.md describes (scipy least
squares + equation-error ranking + simulation-error refits of the two
leaders); not the notes' code. What a careful scipy user would write:

- equations of models/rotary_pendulum.plant written by hand in numpy
  (M(q), bias, generalised forces), parameter values and `estimate` bounds
  read from the model text, and checked at a few states against
  `plantc derive --json` when that file is given;
- simulation by scipy.integrate.solve_ivp with the input held (zero-order
  hold, V[k] over [t_k, t_k+1)): every stretch of constant input is one
  solve_ivp call, so no step straddles an input change (a free swing is one
  call, the driven run one call per sample interval). LSODA on long
  stretches (the stuck arm's smooth dry friction tanh(w/1e-3) is stiff,
  LSODA switches to BDF), RK45 on single sample intervals (cheaper to start;
  2 ms is within its stability limit). rtol 1e-8, atol 1e-10: the
  integration error is far below the 1.5e-3 rad encoder count, and smooth
  enough in the parameters for finite-difference Jacobians. Dry friction
  sign(v) is simulated as tanh(v/1e-3) (the notes, trap 8);
- nominal fit: scipy.optimize.least_squares (trf, the model's bounds) on the
  simulation error of both angles, the 5 `estimate` parameters plus the
  initial velocities of each experiment; a hand-written forward-difference
  Jacobian that simulates an initial-velocity column on its own experiment
  only (steps 1e-4 of each variable's scale);
- equation-error ranking of candidate effects: Savitzky-Golay derivatives
  (scipy.signal.savgol_filter, order 5 over 0.122 s: 61 samples at 500 Hz),
  the input as its average over the interval centred on each sample (the
  notes, trap 2), the force side smoothed by the same kernel (trap 3), the
  arm equation without its stuck samples (trap 4), the nominal parameters
  re-adjusted through nuisance columns (trap 5), linear least squares;
- simulation-error refits of the two leading candidates, and the verdict:
  the refit with the lowest RMSE if it lowers the RMSE 3x or more (plantc's
  own rule), else no effect.

Deterministic (no random numbers; the check states are fixed). Prints the
wall and process CPU time of each phase, and a last line `SUMMARY {json}`
for the bench script.

    python scipy_identify.py MODEL CASE_DIR [--derive-json FILE] [--cap SECONDS]
"""

import argparse
import json
import math
import os
import re
import sys
import time

import numpy as np
import scipy
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares
from scipy.signal import savgol_coeffs, savgol_filter

EXPERIMENTS = ["free_swing_large", "free_swing_small", "driven"]
W_DRY = 1e-3  # tanh width of dry friction in the simulation, rad/s
RTOL, ATOL = 1e-8, 1e-10
FD_STEP = 1e-4  # forward-difference step, relative to each variable's scale
MIN_GAIN = 3.0  # verdict: the effect must lower the RMSE this many times


class Capped(Exception):
    """A phase ran past its time cap."""


class Clock:
    """Wall and process-CPU time of the phases."""

    def __init__(self):
        self.rows = []
        self.w0, self.c0 = time.perf_counter(), time.process_time()

    def start(self):
        self.w, self.c = time.perf_counter(), time.process_time()

    def stop(self, name, note=""):
        w, c = time.perf_counter() - self.w, time.process_time() - self.c
        self.rows.append((name, w, c, note))
        print(f"  [{name}: wall {w:.2f} s, CPU {c:.2f} s{'; ' + note if note else ''}]", flush=True)

    def total(self):
        return time.perf_counter() - self.w0, time.process_time() - self.c0


# ---------------------------------------------------------------- the model


def read_model(path):
    """`parameter NAME = VALUE ... [estimate [lo, hi]]` lines of the model."""
    values, estimate = {}, []
    pat = re.compile(r"^\s*parameter\s+(\w+)\s*=\s*([-+0-9.eE]+)(.*)$")
    for line in open(path):
        m = pat.match(line.split("#")[0])
        if not m:
            continue
        name, value, rest = m.group(1), float(m.group(2)), m.group(3)
        values[name] = value
        e = re.search(r"estimate\s*\[\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+)\s*\]", rest)
        if e:
            estimate.append((name, float(e.group(1)), float(e.group(2))))
    return values, estimate


class Plant:
    """The rotary pendulum (models/rotary_pendulum.plant) at given values.

    M(q) q'' + bias(q, q') = Q(q, q', V), q = (theta, alpha):
      M = [[J0h + J2h sin^2 a, -c cos a], [-c cos a, J2h]]
      bias = [(2 J2h cos a th' + c a') sin a a', -(J2h cos a th'^2 + m2 g l2) sin a]
      Q = [tau - b1 th' - Fg1 sign(th'), -b2 a'] + effects
      tau = eta_g Kg eta_m kt (V - Kg km th') / Rm
    Effects (candidate or added): `(kind, target, value)` with kind
    coulomb (-F sign(q')), quadratic_drag (-cd q'|q'|), spring (-k q),
    added_inertia (J on the coordinate's diagonal of M).
    """

    def __init__(self, p, effects=()):
        self.p = p
        self.J0h = p["J1"] + p["m1"] * p["l1"] ** 2 + p["m2"] * p["L1"] ** 2
        self.J2h = p["J2"] + p["m2"] * p["l2"] ** 2
        self.c = p["m2"] * p["L1"] * p["l2"]
        self.mgl = p["m2"] * p["g"] * p["l2"]
        self.Bv = p["eta_g"] * p["Kg"] * p["eta_m"] * p["kt"] / p["Rm"]
        self.Kb = self.Bv * p["Kg"] * p["km"]
        e = {(k, t): 0.0 for k in ("coulomb", "quadratic_drag", "spring", "added_inertia") for t in ("theta", "alpha")}
        for kind, target, value in effects:
            e[(kind, target)] += value
        self.e = e

    # vectorised pieces, `sgn` the sign law (np.sign or a tanh)
    def mass(self, a):
        s, co = np.sin(a), np.cos(a)
        m00 = self.J0h + self.J2h * s * s + self.e[("added_inertia", "theta")]
        m01 = -self.c * co
        m11 = self.J2h + self.e[("added_inertia", "alpha")] + 0 * a
        return m00, m01, m11

    def bias(self, a, td, ad):
        s, co = np.sin(a), np.cos(a)
        return (2 * self.J2h * co * td + self.c * ad) * s * ad, -(self.J2h * co * td * td + self.mgl) * s

    def forces(self, th, a, td, ad, V, sgn):
        p, e = self.p, self.e
        q0 = self.Bv * V - self.Kb * td - p["b1"] * td - p["Fg1"] * sgn(td)
        q1 = -p["b2"] * ad + 0 * a
        q0 = q0 - e[("coulomb", "theta")] * sgn(td) - e[("quadratic_drag", "theta")] * td * np.abs(td) - e[("spring", "theta")] * th
        q1 = q1 - e[("coulomb", "alpha")] * sgn(ad) - e[("quadratic_drag", "alpha")] * ad * np.abs(ad) - e[("spring", "alpha")] * a
        return q0, q1

    def rhs(self, u):
        """Scalar right-hand side for solve_ivp; the held input is u[0]."""
        J0h, J2h, c, mgl, Bv, Kb = self.J0h, self.J2h, self.c, self.mgl, self.Bv, self.Kb
        p, e = self.p, self.e
        b1, b2, Fg1 = p["b1"], p["b2"], p["Fg1"]
        Ja0, Ja1 = e[("added_inertia", "theta")], e[("added_inertia", "alpha")]
        Fc0, Fc1 = e[("coulomb", "theta")], e[("coulomb", "alpha")]
        cd0, cd1 = e[("quadratic_drag", "theta")], e[("quadratic_drag", "alpha")]
        k0, k1 = e[("spring", "theta")], e[("spring", "alpha")]
        extra = any(v != 0.0 for v in (Fc0, Fc1, cd0, cd1, k0, k1))
        sin, cos, tanh = math.sin, math.cos, math.tanh
        w = W_DRY

        def f(t, x):
            th, al, td, ad = x
            s = sin(al)
            co = cos(al)
            m00 = J0h + J2h * s * s + Ja0
            m01 = -c * co
            m11 = J2h + Ja1
            r0 = Bv * u[0] - (Kb + b1) * td - Fg1 * tanh(td / w) - (2 * J2h * co * td + c * ad) * s * ad
            r1 = -b2 * ad + (J2h * co * td * td + mgl) * s
            if extra:
                r0 -= Fc0 * tanh(td / w) + cd0 * td * abs(td) + k0 * th
                r1 -= Fc1 * tanh(ad / w) + cd1 * ad * abs(ad) + k1 * al
            det = m00 * m11 - m01 * m01
            return [td, ad, (m11 * r0 - m01 * r1) / det, (m00 * r1 - m01 * r0) / det]

        return f


def simulate(plant, exp, x0):
    """Angles at the sample instants, input held over each sample interval."""
    t, V = exp["t"], exp["V"]
    n = len(t)
    u = [0.0]
    f = plant.rhs(u)
    Y = np.empty((n, 2))
    x = np.asarray(x0, float)
    Y[0] = x[:2]
    change = np.flatnonzero(np.diff(V) != 0) + 1
    starts, ends = np.r_[0, change], np.r_[change, n - 1]
    for a, b in zip(starts, ends):
        if b <= a:
            continue
        u[0] = V[a]
        method = "RK45" if b - a == 1 else "LSODA"
        sol = solve_ivp(f, (t[a], t[b]), x, method=method, t_eval=t[a + 1 : b + 1], rtol=RTOL, atol=ATOL)
        if sol.status != 0 or sol.y.shape[1] != b - a:
            raise RuntimeError(f"solve_ivp failed on {exp['name']} at t = {t[a]:.3f}: {sol.message}")
        Y[a + 1 : b + 1] = sol.y[:2].T
        x = sol.y[:, -1]
    return Y


# ---------------------------------------------------------------- checks


def check_against_plantc(values, derive_json):
    """Largest relative difference of M, bias, forces and input matrix from
    `plantc derive --json`, at five fixed states (nominal values)."""
    eq = json.load(open(derive_json))

    def ev(expr, env):
        expr = expr.replace("theta'", "theta_d").replace("alpha'", "alpha_d").replace("^", "**")
        return float(eval(expr, {"__builtins__": {}}, env))

    plant = Plant(values)
    worst = 0.0
    states = [(0.3, 2.9, 1.2, -0.7, 1.5), (-1.0, 0.4, -2.5, 3.1, -4.0), (0.0, math.pi, 0.05, 0.0, 0.2),
              (2.0, -1.2, 0.0, -4.0, 7.5), (-0.4, 1.6, 6.0, 2.2, -0.3)]
    for th, a, td, ad, V in states:
        env = dict(values, sin=math.sin, cos=math.cos, sign=lambda v: float(np.sign(v)), abs=abs, exp=math.exp,
                   theta=th, alpha=a, theta_d=td, alpha_d=ad)
        for k, e in eq["derived"].items():
            env[k] = ev(e, env)
        m00, m01, m11 = plant.mass(np.array(a))
        b0, b1 = plant.bias(np.array(a), td, ad)
        q0, q1 = plant.forces(th, np.array(a), td, ad, 0.0, np.sign)
        mine = {"M": [m00, m01, m01, m11], "bias": [b0, b1], "forces": [q0, q1], "B": [plant.Bv, 0.0]}
        theirs = {
            "M": [ev(x, env) for row in eq["mass_matrix"] for x in row],
            "bias": [ev(x, env) for x in eq["bias"]],
            "forces": [ev(x, env) for x in eq["forces"]],
            "B": [ev(row[0], env) for row in eq["input_matrix"]],
        }
        for k in mine:
            for x, y in zip(mine[k], theirs[k]):
                worst = max(worst, abs(float(x) - y) / max(1e-12, abs(y), 1e-6))
        # the scalar right-hand side against M^-1 (Q - bias) of plantc's terms
        f = plant.rhs([V])
        acc = f(0.0, [th, a, td, ad])[2:]
        M = np.array(theirs["M"]).reshape(2, 2)
        Q = np.array(theirs["forces"]) + np.array(theirs["B"]) * V
        # plantc's forces use sign(); the simulation uses tanh(v/1e-3): the
        # states above have |theta'| >= 0.05 rad/s or theta' = 0, where they
        # agree to 1e-21 (tanh(50)) or both vanish
        ref = np.linalg.solve(M, Q - np.array(theirs["bias"]))
        worst = max(worst, float(np.max(np.abs(np.array(acc) - ref) / np.maximum(1e-6, np.abs(ref)))))
    return worst


# ---------------------------------------------------------------- fitting


class SimFit:
    """Simulation-error least squares over the experiments."""

    def __init__(self, values, estimate, exps, effect, clock_cap):
        self.values, self.exps, self.effect = values, exps, effect
        self.names = [n for n, _, _ in estimate]
        lo = [l for _, l, _ in estimate]
        hi = [h for _, _, h in estimate]
        scale = [max(abs(values[n]), 1e-3 * (h - l)) for n, l, h in estimate]
        if effect is not None:
            lo.append(0.0)
            hi.append(10.0)
            scale.append(max(effect[2], 1e-4))
        for _ in exps:
            lo += [-50.0, -50.0]
            hi += [50.0, 50.0]
            scale += [0.1, 0.1]
        self.lo, self.hi, self.scale = np.array(lo), np.array(hi), np.array(scale)
        self.np = len(self.names) + (effect is not None)
        self.sims = 0
        self.deadline = clock_cap
        self.best = (math.inf, None)
        self.cache = {}

    def plant(self, x):
        p = dict(self.values)
        for n, v in zip(self.names, x):
            p[n] = v
        eff = [] if self.effect is None else [(self.effect[0], self.effect[1], x[len(self.names)])]
        return Plant(p, eff)

    def residual_exp(self, plant, i, x):
        exp = self.exps[i]
        v = x[self.np + 2 * i : self.np + 2 * i + 2]
        self.sims += 1
        if time.perf_counter() > self.deadline:
            raise Capped()
        Y = simulate(plant, exp, [exp["theta"][0], exp["alpha"][0], v[0], v[1]])
        return np.concatenate([Y[:, 0] - exp["theta"], Y[:, 1] - exp["alpha"]])

    def residual(self, x):
        key = x.tobytes()
        if key in self.cache:
            return np.concatenate(self.cache[key])
        plant = self.plant(x)
        parts = [self.residual_exp(plant, i, x) for i in range(len(self.exps))]
        self.cache = {key: parts}
        r = np.concatenate(parts)
        cost = float(r @ r)
        if cost < self.best[0]:
            self.best = (cost, x.copy())
        return r

    def jacobian(self, x):
        base = self.cache.get(x.tobytes())
        if base is None:
            self.residual(x)
            base = self.cache[x.tobytes()]
        sizes = [len(b) for b in base]
        offs = np.r_[0, np.cumsum(sizes)]
        J = np.zeros((offs[-1], len(x)))
        for j in range(len(x)):
            h = FD_STEP * self.scale[j]
            if x[j] + h > self.hi[j]:
                h = -h
            xj = x.copy()
            xj[j] += h
            if j < self.np:  # a parameter: every experiment
                plant = self.plant(xj)
                for i in range(len(self.exps)):
                    J[offs[i] : offs[i + 1], j] = (self.residual_exp(plant, i, xj) - base[i]) / h
            else:  # an initial velocity: its own experiment only
                i = (j - self.np) // 2
                J[offs[i] : offs[i + 1], j] = (self.residual_exp(self.plant(xj), i, xj) - base[i]) / h
        return J

    def fit(self, x0):
        """Returns (x, rmse, capped, message)."""
        x0 = np.clip(np.asarray(x0, float), self.lo, self.hi)
        try:
            res = least_squares(self.residual, x0, jac=self.jacobian, bounds=(self.lo, self.hi), method="trf",
                                x_scale=self.scale, ftol=1e-6, xtol=1e-6, gtol=1e-8, max_nfev=100)
            x, msg, capped = res.x, f"{res.nfev} evaluations, {res.message}", False
        except Capped:
            x, msg, capped = self.best[1], "time cap reached: best point so far", True
        r = self.residual(x)
        return x, math.sqrt(float(r @ r) / len(r)), capped, msg


def rmse_at(values, exps, effects=()):
    plant = Plant(values, effects)
    r = []
    for exp in exps:
        Y = simulate(plant, exp, [exp["theta"][0], exp["alpha"][0], 0.0, 0.0])
        r += [Y[:, 0] - exp["theta"], Y[:, 1] - exp["alpha"]]
    r = np.concatenate(r)
    return math.sqrt(float(r @ r) / len(r))


# ---------------------------------------------------------------- equation error

CANDIDATES = [
    ("coulomb", "alpha"),
    ("quadratic_drag", "alpha"),
    ("spring", "alpha"),
    ("added_inertia", "alpha"),
    ("coulomb", "theta"),
    ("quadratic_drag", "theta"),
    ("spring", "theta"),
]


def equation_error_ranking(values, estimate, exps):
    """Candidates ranked by the BIC gain of their column, nuisance columns of
    the `estimate` parameters re-adjusted; returns (rows, notes)."""
    names = [n for n, _, _ in estimate]
    rate = 1.0 / float(np.median(np.diff(exps[0]["t"])))
    half = int(round(0.061 * rate))
    win, order = 2 * half + 1, 5
    T = 1.0 / rate
    quantum = 2 * math.pi / 4096
    c1 = savgol_coeffs(win, order, deriv=1, delta=T)
    c2 = savgol_coeffs(win, order, deriv=2, delta=T)
    vel_noise = quantum / math.sqrt(12) * math.sqrt(float(c1 @ c1))
    acc_noise = quantum / math.sqrt(12) * math.sqrt(float(c2 @ c2))
    v_stuck = 5 * vel_noise
    smooth = lambda y: savgol_filter(y, win, order, mode="interp")
    sgn = np.sign

    pre = []
    for exp in exps:
        d = {}
        for k in ("theta", "alpha"):
            d[k] = smooth(exp[k])
            d[k + "_d"] = savgol_filter(exp[k], win, order, deriv=1, delta=T, mode="interp")
            d[k + "_dd"] = savgol_filter(exp[k], win, order, deriv=2, delta=T, mode="interp")
        V = exp["V"]
        d["V"] = np.r_[V[0], 0.5 * (V[:-1] + V[1:])]  # ZOH average over [t_k - T/2, t_k + T/2)
        keep = np.zeros(len(V), bool)
        keep[half:-half] = True
        stuck = np.abs(d["theta_d"]) < v_stuck
        stuck_wide = np.convolve(stuck.astype(float), np.ones(win), mode="same") > 0
        d["keep_alpha"] = keep
        d["keep_theta"] = keep & ~stuck_wide
        pre.append(d)

    def eq_residual(p, effect=None):
        """Stacked (theta rows, alpha rows) of M q'' + bias - Q, force side
        smoothed by the same kernel as the accelerations."""
        plant = Plant(p, [] if effect is None else [effect])
        rows = []
        for d in pre:
            th, a, td, ad = d["theta"], d["alpha"], d["theta_d"], d["alpha_d"]
            m00, m01, m11 = plant.mass(a)
            b0, b1 = plant.bias(a, td, ad)
            q0, q1 = plant.forces(th, a, td, ad, d["V"], sgn)
            e0 = m00 * d["theta_dd"] + m01 * d["alpha_dd"] + smooth(b0 - q0)
            e1 = m01 * d["theta_dd"] + m11 * d["alpha_dd"] + smooth(b1 - q1)
            rows.append((e0[d["keep_theta"]], e1[d["keep_alpha"]]))
        return rows

    def stack(rows, w0, w1):
        return np.concatenate([np.concatenate([r0 * w0 for r0, _ in rows]), np.concatenate([r1 * w1 for _, r1 in rows])])

    base_rows = eq_residual(values)
    w0 = 1.0 / math.sqrt(np.mean(np.concatenate([r for r, _ in base_rows]) ** 2))
    w1 = 1.0 / math.sqrt(np.mean(np.concatenate([r for _, r in base_rows]) ** 2))
    r = stack(base_rows, w0, w1)
    N = len(r)
    nuis = []
    for n in names:
        p = dict(values)
        h = 1e-6 * max(abs(values[n]), 1e-6)
        p[n] += h
        nuis.append((stack(eq_residual(p), w0, w1) - r) / h)
    Nm = np.column_stack(nuis)
    delta, _, rank, _ = np.linalg.lstsq(Nm, -r, rcond=None)
    rss0 = float(np.sum((r + Nm @ delta) ** 2))
    notes = [f"{N} equations ({sum(len(a) for a, _ in base_rows)} arm, {sum(len(b) for _, b in base_rows)} pendulum; "
             f"arm samples with |theta'| < {v_stuck:.3f} rad/s dropped with a half window), "
             f"Savitzky-Golay {win} samples order {order}: quantisation gives {vel_noise:.3f} rad/s, {acc_noise:.2f} rad/s^2 of noise",
             f"nuisance columns of {', '.join(names)}: rank {rank} of {len(names)}"]
    out = []
    for kind, target in CANDIDATES:
        p1 = 1e-4  # the column is linear in the effect's value: a unit step
        col = (stack(eq_residual(values, (kind, target, p1)), w0, w1) - r) / p1
        A = np.column_stack([Nm, col])
        # the part of the column the nuisance columns cannot make
        proj = col - Nm @ np.linalg.lstsq(Nm, col, rcond=None)[0]
        if np.linalg.norm(proj) < 1e-6 * np.linalg.norm(col):
            out.append(dict(kind=kind, target=target, value=float("nan"), share=0.0, bic=float("-inf"),
                            note="no information: the column is one of the model's own terms"))
            continue
        coef = np.linalg.lstsq(A, -r, rcond=None)[0]
        rss1 = float(np.sum((r + A @ coef) ** 2))
        bic = N * math.log(rss0 / rss1) - math.log(N)
        value = float(coef[-1])
        out.append(dict(kind=kind, target=target, value=value, share=1 - rss1 / rss0, bic=bic,
                        note="" if value > 0 else "wrong sign (a negative friction, drag, spring or inertia)"))
    out.sort(key=lambda c: -c["bic"])
    return out, notes


# ---------------------------------------------------------------- main


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("case")
    ap.add_argument("--derive-json")
    ap.add_argument("--cap", type=float, default=300.0, help="time cap of each fit phase, s")
    args = ap.parse_args()
    clock = Clock()
    print(f"scipy peer (numpy {np.__version__}, scipy {scipy.__version__}), case {args.case}", flush=True)

    clock.start()
    values, estimate = read_model(args.model)
    exps = []
    for name in EXPERIMENTS:
        d = np.loadtxt(os.path.join(args.case, name + ".csv"), delimiter=",", skiprows=1)
        exps.append(dict(name=name, t=d[:, 0], theta=d[:, 1], alpha=d[:, 2], V=d[:, 3]))
    clock.stop("load", f"{len(exps)} x {len(exps[0]['t'])} samples, estimate {', '.join(n for n, _, _ in estimate)}")

    if args.derive_json:
        clock.start()
        worst = check_against_plantc(values, args.derive_json)
        clock.stop("equations vs plantc derive", f"largest relative difference {worst:.1e} at 5 states")
        if worst > 1e-9:
            sys.exit(f"the numpy equations differ from plantc's ({worst:.1e}): fix scipy_identify.py")

    print("1. nominal model at the table values (initial velocities 0)", flush=True)
    clock.start()
    rmse_nominal = rmse_at(values, exps)
    clock.stop("simulate nominal", f"RMSE {rmse_nominal:.4e} rad")

    print("2. nominal fit: least_squares (trf) on the simulation error, 5 parameters + 2 initial velocities per experiment", flush=True)
    clock.start()
    fit0 = SimFit(values, estimate, exps, None, time.perf_counter() + args.cap)
    x0 = [values[n] for n, _, _ in estimate] + [0.0] * (2 * len(exps))
    x_nom, rmse_fit, capped0, msg = fit0.fit(x0)
    fitted = dict(values)
    for (n, _, _), v in zip(estimate, x_nom):
        fitted[n] = float(v)
    clock.stop("nominal fit", f"RMSE {rmse_fit:.4e} rad, {fit0.sims} experiment simulations, {msg}")
    print("   " + ", ".join(f"{n} = {fitted[n]:.5g}" for n, _, _ in estimate), flush=True)

    print("3. equation-error ranking (linear least squares, nuisance columns of the 5 parameters)", flush=True)
    clock.start()
    ranking, notes = equation_error_ranking(fitted, estimate, exps)
    clock.stop("equation-error ranking")
    for n in notes:
        print("   " + n)
    print(f"   {'candidate':<26} {'BIC gain':>10} {'share':>8} {'estimate':>11}")
    for c in ranking:
        print(f"   {c['kind'] + ' on ' + c['target']:<26} {c['bic']:>10.1f} {100 * c['share']:>7.2f}% {c['value']:>11.3e}  {c['note']}")
    leaders = [c for c in ranking if c["value"] > 0 and math.isfinite(c["bic"])][:2]

    print(f"4. simulation-error refits of the two leaders: {', '.join(c['kind'] + ' on ' + c['target'] for c in leaders)}", flush=True)
    refits = []
    capped = capped0
    for c in leaders:
        clock.start()
        fit = SimFit(fitted, estimate, exps, (c["kind"], c["target"], c["value"]), time.perf_counter() + args.cap)
        x1 = list(x_nom[: len(estimate)]) + [c["value"]] + list(x_nom[len(estimate):])
        x, rmse, cap, msg = fit.fit(x1)
        capped = capped or cap
        refits.append(dict(c, fitted=float(x[len(estimate)]), rmse=rmse, gain=rmse_fit / rmse,
                           params={n: float(v) for (n, _, _), v in zip(estimate, x)}))
        clock.stop(f"refit {c['kind']} on {c['target']}", f"RMSE {rmse:.4e} rad ({rmse_fit / rmse:.2f}x), value {x[len(estimate)]:.4e}, "
                   f"{fit.sims} experiment simulations, {msg}")

    best = min(refits, key=lambda c: c["rmse"]) if refits else None
    if best is not None and best["gain"] >= MIN_GAIN:
        verdict = f"{best['kind']} on {best['target']}"
        line = (f"missing effect: {verdict} = {best['fitted']:.4e} (RMSE {rmse_fit:.3e} -> {best['rmse']:.3e}, "
                f"{best['gain']:.2f}x lower)")
        rmse_after, effect_value = best["rmse"], best["fitted"]
    else:
        verdict = "none"
        line = f"no candidate lowers the RMSE {MIN_GAIN}x (best {best['gain']:.2f}x)" if best else "no candidate"
        rmse_after, effect_value = rmse_fit, None
    print("5. verdict: " + line)
    if best is not None and verdict != "none":
        print("   " + ", ".join(f"{n} = {v:.5g}" for n, v in best["params"].items()))
    truth = os.path.join(args.case, "truth.json")
    if os.path.exists(truth):  # read only now, for the reader
        tj = json.load(open(truth))
        print(f"   truth.json (read after the verdict): {tj.get('effect')} on {tj.get('coordinate')} {tj.get('effect_parameters')}")
    w, c = clock.total()
    print(f"RMSE {rmse_nominal:.4e} (nominal) -> {rmse_fit:.4e} (refitted) -> {rmse_after:.4e} (with the effect): "
          f"{rmse_nominal / rmse_after:.1f}x lower")
    print(f"total: wall {w:.1f} s, CPU {c:.1f} s{' (a phase hit its time cap)' if capped else ''}")
    print("SUMMARY " + json.dumps(dict(wall=w, cpu=c, verdict=verdict, rmse_nominal=rmse_nominal, rmse_refit=rmse_fit,
                                       rmse_after=rmse_after, effect_value=effect_value, capped=capped,
                                       phases=[dict(name=n, wall=pw, cpu=pc) for n, pw, pc, _ in clock.rows])))


if __name__ == "__main__":
    main()
