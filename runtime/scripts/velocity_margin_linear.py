#!/usr/bin/env python3
"""Linear analysis behind the runtime's velocity-estimator choice.

Slowest growth rate (1/s, > 0 = unstable) of the sampled closed loop
(1 kHz, ZOH) of the rotary pendulum linearized about upright, with the
controller fed (a) exact states, (b) Quanser's Tustin filtered derivative
wc s/(s + wc) at several wc. The feedback-linearizing law fl_arm is
linearized analytically: u = (v - A[3] x) / B[3] with
v = -wn^2 alpha - 2 zeta wn alpha' + a theta + b theta' (wn = 4, zeta = 0.7).
No quantisation. Needs numpy and scipy.

Usage: plantc linearize models/rotary_pendulum.plant --set thesis --json > lin.json
       python3 runtime/scripts/velocity_margin_linear.py lin.json
"""
import json
import sys

import numpy as np
import scipy.linalg as sl

T = 1e-3
lin = json.load(open(sys.argv[1]))
A = np.array(lin["A"])
B = np.array(lin["B"])
M = sl.expm(np.block([[A, B], [np.zeros((1, 5))]]) * T)
Ad, Bd = M[:4, :4], M[:4, 4]
C = np.zeros((2, 4))
C[0, 0] = C[1, 1] = 1


def fl_gain(a, b, wn=4.0, zeta=0.7):
    v = np.array([a, -wn**2, b, -2 * zeta * wn])
    return (v - A[3]) / B[3, 0]


def rate(F):
    return np.log(max(abs(np.linalg.eigvals(F)))) / T


def exact(G):
    return rate(Ad + np.outer(Bd, G))


def derivative(G, wc):
    # z[k] = [x[k], y[k-1], q[k-1]]; y[k] = al y[k-1] + be (q[k] - q[k-1]); u = Gq q + Gv y
    al, be = (2 - wc * T) / (2 + wc * T), 2 * wc / (2 + wc * T)
    Yx, Yy, Yq = be * C, al * np.eye(2), -be * np.eye(2)
    ux = G[:2] @ C + G[2:] @ Yx
    F = np.zeros((8, 8))
    F[:4, :4] = Ad + np.outer(Bd, ux)
    F[:4, 4:6] = np.outer(Bd, G[2:] @ Yy)
    F[:4, 6:8] = np.outer(Bd, G[2:] @ Yq)
    F[4:6, :4], F[4:6, 4:6], F[4:6, 6:8] = Yx, Yy, Yq
    F[6:8, :4] = C
    return rate(F)


bws = (50, 100, 200, 400, 1000, 2000)
print("controller          exact  " + " ".join("wc=%-5d" % w for w in bws))
for g in (0.1, 0.3, 0.5, 0.7, 0.9, 1.0):
    G = fl_gain(g, g)
    print("fl_arm a=b=%-4.2f   %+.3f " % (g, exact(G)) + " ".join("%+7.3f" % derivative(G, w) for w in bws))
print("theta' gain of fl_arm a=b=0.5: %.3f V/(rad/s); back-EMF damping A[2,2]/B[2] = %.3f"
      % (fl_gain(0.5, 0.5)[2], -A[2, 2] / B[2, 0]))
