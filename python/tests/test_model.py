"""Loading models: diagnostics as exceptions, equations."""

import os

import pytest

import plantc
from conftest import model_path

GOOD = """model spring_mass "a mass on a spring"

coordinate x : length "position"
input F [N] "force"
output x

parameter m = 1.5 [kg] "mass"
parameter k = 20 [N/m] "stiffness"

kinetic T = 1/2*m*x'^2
potential V = 1/2*k*x^2

force x = F
"""


def test_load_a_bundled_model():
    m = plantc.Model.load(model_path("rotary_pendulum.plant"))
    assert m.name.endswith("rotary_pendulum.plant")
    assert "coordinate theta" in m.text


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError) as e:
        plantc.Model.load(tmp_path / "nope.plant")
    assert "nope.plant" in str(e.value)


def test_bad_text_raises_model_error_with_line_and_column():
    # line 12 (1-based), `kk` is not declared: the error points at it
    bad = GOOD.replace("potential V = 1/2*k*x^2", "potential V = 1/2*kk*x^2")
    with pytest.raises(plantc.ModelError) as e:
        plantc.Model.from_text(bad, name="bad.plant")
    err = e.value
    assert err.file == "bad.plant"
    assert err.line == 11
    assert err.column == bad.splitlines()[10].index("kk") + 1
    assert "kk" in str(err)
    assert err.diagnostics[0][0] == "error"
    assert isinstance(err, plantc.PlantcError)


def test_bad_file_reports_its_path(tmp_path):
    p = tmp_path / "broken.plant"
    p.write_text(GOOD.replace("force x = F", "force x = F +"))
    with pytest.raises(plantc.ModelError) as e:
        plantc.Model.load(p)
    assert e.value.file == str(p)
    assert e.value.line >= 13
    assert str(p) in str(e.value)


def test_non_utf8_file_is_a_model_error(tmp_path):
    p = tmp_path / "latin1.plant"
    p.write_bytes(GOOD.encode() + b"# caf\xe9\n")
    with pytest.raises(plantc.ModelError) as e:
        plantc.Model.load(p)
    assert e.value.line == GOOD.count("\n") + 1


def test_derive_gives_printed_and_latex_forms():
    m = plantc.Model.from_text(GOOD)
    eq = m.derive()
    assert eq.coordinates == ["x"]
    assert eq.state == ["x", "x_dot"]
    # M = m; x'' = (F - k x)/m, printed over D = det M = m, and g = 1/D
    assert eq.mass_matrix == [["m"]]
    assert eq.det_mass == "m"
    assert eq.f == ["x'", "-k*x/D"]
    assert eq.g[1] == ["1/D"]
    assert eq.latex.mass_matrix == [["m"]]
    assert "\\frac" in eq.latex.f[1] or "/" in eq.latex.f[1]


def test_derive_sympy_when_installed():
    sympy = pytest.importorskip("sympy")
    m = plantc.Model.load(model_path("rotary_pendulum.plant"))
    s = m.derive().sympy()
    M = s["mass_matrix"]
    assert len(M) == 2 and all(isinstance(e, sympy.Expr) for r in M for e in r)
    # the mass matrix is symmetric (printed separately, parsed separately)
    assert sympy.simplify(M[0][1] - M[1][0]) == 0


def test_warnings_are_kept():
    m = plantc.Model.load(model_path("rotary_pendulum.plant"))
    assert isinstance(m.warnings, list)
