"""Simulation to numpy, equal to `plantc sim`'s CSV."""

import numpy as np
import pytest

import plantc
from conftest import model_path

PEND = model_path("rotary_pendulum.plant")


def test_pole_placement_balances():
    m = plantc.Model.load(PEND)
    tr = m.simulate("pole_placement", x0={"alpha": np.radians(5)}, duration=5.0)
    n = len(tr.t)
    assert tr.states.shape == (n, 4) and tr.inputs.shape == (n, 1)
    assert tr.state_names == ["theta", "alpha", "theta_dot", "alpha_dot"]
    assert tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(5.0)
    # the placed poles (slowest -2 +- 3.46i) leave e^-10 of the start after 5 s
    assert abs(tr["alpha"][-1]) < 1e-3
    assert abs(tr["alpha"][0] - np.radians(5)) < 1e-15


def test_simulation_equals_the_cli_csv(tmp_path):
    m = plantc.Model.load(PEND)
    tr = m.simulate("pole_placement", x0={"alpha": 0.1}, duration=2.0, set="thesis")
    out = tmp_path / "pp.csv"
    code, _, err = plantc.cli("sim", PEND, "--set", "thesis", "--controller", "pole_placement",
                              "--x0", "alpha=0.1", "--duration", "2", "-o", str(out))
    assert code == 0, err
    csv = np.genfromtxt(out, delimiter=",", names=True)
    assert np.array_equal(csv["t"], tr.t)
    for name in tr.state_names + tr.input_names:
        assert np.array_equal(csv[name], tr[name]), name


def test_to_pandas():
    pd = pytest.importorskip("pandas")
    tr = plantc.Model.load(PEND).simulate("pole_placement", x0={"alpha": 0.05}, duration=1.0)
    df = tr.to_pandas()
    assert isinstance(df, pd.DataFrame)
    assert list(df.columns[:6]) == ["t", "theta", "alpha", "theta_dot", "alpha_dot", "Vm"]


def test_bad_arguments():
    m = plantc.Model.load(PEND)
    with pytest.raises(ValueError, match="not a state"):
        m.simulate("pole_placement", x0={"phi": 1.0}, duration=1.0)
    with pytest.raises(ValueError, match="must be positive"):
        m.simulate("pole_placement", duration=-1.0)
    with pytest.raises(ValueError, match="no_such"):
        m.simulate("no_such", duration=1.0)


def test_analyze_mirrors_the_cli_json():
    r = plantc.Model.load(PEND).analyze(output="alpha")
    code, out, _ = plantc.cli("analyze", PEND, "--output", "alpha", "--json")
    import json
    assert code == 0 and r.json == json.loads(out)
