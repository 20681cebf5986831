#!/usr/bin/env python3
"""Independent reference numbers for derive/tests/linear_thesis.rs.

LQR of the thesis' linear model (Eq. 3-4, rotary pendulum) with Q = I4, R = 1,
computed with scipy.linalg.solve_continuous_are. Regenerate with

    python3 -m venv /tmp/venv-scipy && /tmp/venv-scipy/bin/pip install scipy numpy
    /tmp/venv-scipy/bin/python bench/lqr_reference.py
"""
import numpy as np
import scipy
from scipy.linalg import solve_continuous_are
from scipy.signal import place_poles

A = np.array([
    [0, 0, 1, 0],
    [0, 0, 0, 1],
    [0, 81.4033, -45.8259, -0.9319],
    [0, 122.0545, -44.0966, -1.3972],
])
B = np.array([[0], [0], [83.4659], [80.3162]])
Q = np.eye(4)
R = np.array([[1.0]])

P = solve_continuous_are(A, B, Q, R)
K = np.linalg.solve(R, B.T @ P)
res = A.T @ P + P @ A - P @ B @ np.linalg.solve(R, B.T @ P) + Q
print(f"# numpy {np.__version__}, scipy {scipy.__version__}")
print("# P = solve_continuous_are(A, B, np.eye(4), np.array([[1.0]])); K = solve(R, B.T @ P)")
print("K =", np.array2string(K, precision=17, separator=", ", max_line_width=200))
print("P =", np.array2string(P, precision=17, separator=", ", max_line_width=200))
print("closed-loop poles =", np.sort_complex(np.linalg.eigvals(A - B @ K)))
print("residual ||.||_F =", np.linalg.norm(res))

for poles in ([-2 + 3.464j, -2 - 3.464j, -40, -45], [-2.1467, -7.4533, -40, -45]):
    print("place", poles, "K =", place_poles(A, B, poles).gain_matrix)
