"""The README's main job from Python, and an LQR design cross-checked.

    python python/examples/main_job.py [OUT_DIR]

1. identify: the nominal rotary pendulum against data/demo_two_effects ->
   where it fails -> the missing effects, added and fitted round by round ->
   before/after table (the same story, numbers and files as
   `plantc identify models/rotary_pendulum.plant data/demo_two_effects/*.csv -o OUT_DIR`);
2. LQR on the model linearised with the thesis' values, checked against
   python-control's `lqr` when installed (else against the Riccati equation
   in numpy).

In Jupyter, `story` (the last expression of a cell) shows the table and the
figures inline.
"""

import glob
import os
import sys

import numpy as np

import plantc

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def identify(out):
    """The main job: returns the identify result."""
    model = plantc.Model.load(os.path.join(ROOT, "models", "rotary_pendulum.plant"))
    data = sorted(glob.glob(os.path.join(ROOT, "data", "demo_two_effects", "*.csv")))
    story = model.identify(data, out=out, force=True)
    print(f"verdict: {story.verdict} ({story.stop})")
    for r in story.rounds:
        print(f"  round: {r.effect} on {r.target}")
    for s in story.simplified:
        print(f"  simplified: {s['from']} -> {s.to}")
    print("before/after (RMSE, all channels):")
    for s in story.stages:
        print(f"  {s.stage:<55} {s.report.rmse:.3e}")
    for name, p in story.fit.parameters.items():
        print(f"  {name:<10} = {p.value:.5e}  (std error {p.std_error:.1e})")
    print(f"fitted model -> {os.path.join(out, 'fitted.plant')}")
    return story


def lqr_design():
    """LQR on the linearised pendulum; returns (K, the peer's K or None)."""
    model = plantc.Model.load(os.path.join(ROOT, "models", "rotary_pendulum.plant"))
    lin = model.linearize(set="thesis")
    Q, R = np.diag([10.0, 50.0, 1.0, 1.0]), np.array([[0.5]])
    design = plantc.lqr(lin.A, lin.B, Q, R)
    print("LQR K =", design.K.ravel(), " closed-loop poles:", np.round(design.closed_loop_poles, 4))
    try:
        import control
    except ImportError:
        # no python-control: the CARE in numpy instead
        P = design.P
        res = lin.A.T @ P + P @ lin.A - P @ lin.B @ np.linalg.solve(R, lin.B.T @ P) + Q
        print(f"python-control not installed; CARE residual {np.abs(res).max():.2e} (max |P| {np.abs(P).max():.2e})")
        return design.K, None
    K_ref, _, _ = control.lqr(lin.A, lin.B, Q, R)
    rel = np.abs(design.K - K_ref).max() / np.abs(K_ref).max()
    print(f"python-control lqr: K = {np.asarray(K_ref).ravel()}, relative difference {rel:.1e}")
    return design.K, np.asarray(K_ref)


if __name__ == "__main__":
    identify(sys.argv[1] if len(sys.argv) > 1 else "identify-out")
    lqr_design()
