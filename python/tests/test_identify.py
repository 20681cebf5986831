"""The identification workflows on the bundled data, against the CLI."""

import glob
import json
import math
import os

import numpy as np
import pytest

import plantc
from conftest import data_dir, model_path, run_cli

PEND = model_path("rotary_pendulum.plant")
TWO = sorted(glob.glob(os.path.join(data_dir("demo_two_effects"), "*.csv")))
COULOMB = sorted(glob.glob(os.path.join(data_dir("demo_coulomb"), "*.csv")))


def close(a, b, rel=1e-12):
    """Same numbers to `rel` relative (the issue's acceptance), recursively."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys()
        for k in a:
            if k in ("seconds", "model", "files"):
                continue  # wall time; the model's path as given
            close(a[k], b[k], rel)
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b)
        for x, y in zip(a, b):
            close(x, y, rel)
    elif isinstance(a, float) and isinstance(b, (int, float)):
        assert math.isclose(a, b, rel_tol=rel, abs_tol=0.0) or a == b, (a, b)
    else:
        assert a == b


def example():
    """python/examples/main_job.py, imported from its file."""
    import importlib.util

    path = os.path.join(os.path.dirname(__file__), "..", "examples", "main_job.py")
    spec = importlib.util.spec_from_file_location("main_job", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def story(tmp_path_factory):
    # the example script's main job (its output is this test's input)
    out = str(tmp_path_factory.mktemp("py") / "identify-out")
    return example().identify(out), out


def test_the_example_lqr_cross_check():
    K, K_ref = example().lqr_design()
    if K_ref is None:
        pytest.skip("python-control not installed")
    # the acceptance: python-control's lqr to 1e-8
    assert np.abs(K - K_ref).max() <= 1e-8 * np.abs(K_ref).max()


def test_the_main_job_finds_both_effects(story):
    r, out = story
    # data/demo_two_effects/truth.json: dry friction in the pendulum joint
    # (Fc_alpha = 6e-4 N m) and a 4 ms input delay, neither in the model
    with open(os.path.join(data_dir("demo_two_effects"), "truth.json")) as f:
        truth = json.load(f)["effect_parameters"]
    assert r.verdict == "missing_effect"
    assert [x.target for x in r.rounds] == ["alpha", "Vm"]
    assert r.rounds[1].effect == "input_delay"
    fitted = r.fitted
    assert "coulomb_friction(" in fitted.text and "input_delay(" in fitted.text
    est = {k: v["value"] for k, v in r.json["fit"]["parameters"].items()}
    # within 5 % of the truth (the README: 5.99e-4 N m and 3.90 ms found)
    for name, value in truth.items():
        assert est[name] == pytest.approx(value, rel=0.05), name
    assert os.path.isfile(os.path.join(out, "fitted.plant"))


def test_the_main_job_equals_the_cli(story, plantc_bin, tmp_path):
    r, _ = story
    cli_out = tmp_path / "cli-out"
    j = json.loads(run_cli(plantc_bin, "identify", PEND, *TWO, "-o", str(cli_out), "--json"))
    close(r.json, j)


def test_repr_html_shows_the_table_and_figures(story):
    r, _ = story
    h = r._repr_html_()
    assert "<table>" in h and "RMSE, all channels" in h
    for s in r.stages:
        assert s.stage in h
    assert "<svg" in h


def test_compare_fit_diagnose_mirror_the_cli_json(tmp_path):
    m = plantc.Model.load(PEND)
    c = m.compare(COULOMB)
    code, out, err = plantc.cli("compare", PEND, *COULOMB, "--json")
    assert code == 0, err
    close(c.json, json.loads(out))
    assert c.rmse > 0
    f = m.fit(COULOMB, out=tmp_path / "fitted.plant")
    assert os.path.isfile(tmp_path / "fitted.plant")
    assert f.parameters.json and all(math.isfinite(p["value"]) for p in f.parameters.json.values())
    d = m.diagnose(COULOMB)
    # data/demo_coulomb/truth.json: dry friction in the pendulum joint
    assert d.findings[0].target == "alpha"
    assert d.findings[0].effect in ("coulomb_friction", "stribeck_friction")


def test_dataframes_are_data():
    pd = pytest.importorskip("pandas")
    frames = {os.path.splitext(os.path.basename(p))[0]: pd.read_csv(p) for p in COULOMB}
    a = plantc.Model.load(PEND).compare(frames)
    b = plantc.Model.load(PEND).compare(COULOMB)
    close(a.json["rmse"], b.json["rmse"], rel=1e-12)


def test_structured_arrays_are_data():
    arrays = {
        os.path.splitext(os.path.basename(p))[0]: np.genfromtxt(p, delimiter=",", names=True)
        for p in COULOMB
    }
    a = plantc.Model.load(PEND).compare(arrays)
    b = plantc.Model.load(PEND).compare(COULOMB)
    close(a.json["rmse"], b.json["rmse"], rel=1e-12)
    with pytest.raises(TypeError, match="field names"):
        plantc.Model.load(PEND).compare([np.zeros((3, 4))])


def test_missing_data_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        plantc.Model.load(PEND).compare([tmp_path / "none.csv"])


def test_bad_data_is_a_value_error(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("t,x\n0,1\n")
    with pytest.raises(ValueError):
        plantc.Model.load(PEND).compare([p])
