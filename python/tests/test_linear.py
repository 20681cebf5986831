"""Linearization and state-feedback design against the CLI and peers."""

import json

import numpy as np
import pytest

import plantc
from conftest import model_path, run_cli

PEND = model_path("rotary_pendulum.plant")


def test_linearize_equals_the_cli_json_in_process():
    m = plantc.Model.load(PEND)
    lin = m.linearize(set="quanser_manual")
    code, out, err = plantc.cli("linearize", PEND, "--set", "quanser_manual", "--json")
    assert code == 0, err
    j = json.loads(out)
    assert lin.state == j["state"] and lin.inputs == j["inputs"]
    assert np.array_equal(lin.A, np.array(j["A"]))
    assert np.array_equal(lin.B, np.array(j["B"]))
    assert lin.A.shape == (4, 4) and lin.B.shape == (4, 1)


def test_linearize_equals_the_cli_binary(plantc_bin):
    m = plantc.Model.load(PEND)
    lin = m.linearize(set="quanser_manual", at={"alpha": 0.01})
    j = json.loads(run_cli(plantc_bin, "linearize", PEND, "--set", "quanser_manual", "--at", "alpha=0.01", "--json"))
    assert np.array_equal(lin.A, np.array(j["A"]))
    assert np.array_equal(lin.B, np.array(j["B"]))


def test_linearize_thesis_values():
    # thesis Eq. 3-4 as printed (derive/tests/linear_thesis.rs, from
    # ../shared/reference/rotary-pendulum.md); the README: within 0.12 %
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1],
                  [0, 81.4033, -45.8259, -0.9319], [0, 122.0545, -44.0966, -1.3972]])
    B = np.array([[0], [0], [83.4659], [80.3162]])
    lin = plantc.Model.load(PEND).linearize(set="quanser_manual")
    nz = A != 0
    assert np.all(lin.A[~nz] == 0)
    assert np.abs(lin.A[nz] / A[nz] - 1).max() < 1.2e-3
    assert np.abs(lin.B[2:] / B[2:] - 1).max() < 1.2e-3


def test_output_matrices():
    # `output alpha`: y = alpha, so C selects the second state and D = 0
    lin = plantc.Model.load(PEND).linearize()
    assert lin.outputs == ["alpha"]
    assert np.array_equal(lin.C, np.array([[0.0, 1.0, 0.0, 0.0]]))
    assert np.array_equal(lin.D, np.zeros((1, 1)))


def test_unknown_operating_point_name_is_a_value_error():
    with pytest.raises(ValueError, match="not a state or input"):
        plantc.Model.load(PEND).linearize(at={"beta": 1.0})


def test_unknown_set_is_a_value_error():
    with pytest.raises(ValueError, match="nope"):
        plantc.Model.load(PEND).linearize(set="nope")


def test_lqr_solves_the_riccati_equation():
    # independent check in numpy: A'P + PA - P B R^-1 B' P + Q = 0, K = R^-1 B' P
    lin = plantc.Model.load(PEND).linearize(set="quanser_manual")
    Q, R = np.diag([1.0, 1.0, 1.0, 1.0]), np.array([[1.0]])
    d = plantc.lqr(lin.A, lin.B, Q, R)
    A, B, P, K = lin.A, lin.B, d.P, d.K
    res = A.T @ P + P @ A - P @ B @ np.linalg.solve(R, B.T @ P) + Q
    assert np.abs(res).max() < 1e-8 * np.abs(P).max() * np.abs(A).max()
    assert np.allclose(K, np.linalg.solve(R, B.T @ P), rtol=1e-10, atol=0)
    assert np.all(np.linalg.eigvals(A - B @ K).real < 0)


def test_lqr_equals_the_cli(plantc_bin):
    m = plantc.Model.load(PEND)
    d = m.lqr(Q=[1, 1, 1, 1], R=[1], set="quanser_manual")
    j = json.loads(run_cli(plantc_bin, "lqr", PEND, "--set", "quanser_manual", "--q", "1,1,1,1", "--r", "1", "--json"))
    assert np.array_equal(d.K, np.array(j["K"]))


def test_lqr_equals_python_control():
    control = pytest.importorskip("control")
    lin = plantc.Model.load(PEND).linearize(set="quanser_manual")
    Q, R = np.diag([10.0, 50.0, 1.0, 1.0]), np.array([[0.5]])
    K_ref, P_ref, _ = control.lqr(lin.A, lin.B, Q, R)
    d = plantc.lqr(lin.A, lin.B, Q, R)
    # the acceptance: python-control's lqr to 1e-8 (relative)
    assert np.abs(d.K - K_ref).max() <= 1e-8 * np.abs(K_ref).max()
    assert np.abs(d.P - P_ref).max() <= 1e-8 * np.abs(P_ref).max()


def test_place_puts_the_poles_there():
    lin = plantc.Model.load(PEND).linearize(set="quanser_manual")
    want = [-2 + 3.464j, -2 - 3.464j, -40, -45]
    d = plantc.place(lin.A, lin.B, want)
    got = np.sort_complex(np.linalg.eigvals(lin.A - lin.B @ d.K))
    assert np.allclose(got, np.sort_complex(np.array(want)), rtol=1e-8)
    assert np.allclose(np.sort_complex(d.closed_loop_poles), got, rtol=1e-8)


def test_bad_matrices_are_value_errors():
    with pytest.raises(ValueError):
        plantc.lqr([[1.0, 2.0], [3.0]], [[1.0], [0.0]], [1, 1], [1])
    with pytest.raises(ValueError):
        plantc.lqr([[np.nan]], [[1.0]], [1], [1])


def test_uncontrollable_pair_is_a_plantc_error():
    with pytest.raises(plantc.PlantcError):
        plantc.lqr(np.eye(2), np.array([[1.0], [0.0]]) * 0, np.eye(2), [1])
