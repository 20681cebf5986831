"""plantc from Python: the plantc Rust libraries in a wheel.

    import plantc
    m = plantc.Model.load("models/rotary_pendulum.plant")
    lin = m.linearize(set="quanser_manual")          # numpy A, B, C, D
    K = m.lqr(Q=[1, 1, 1, 1], R=[1], set="quanser_manual").K
    traj = m.simulate("pole_placement", x0={"alpha": 0.1}, duration=5)
    story = m.identify(glob.glob("data/demo_two_effects/*.csv"), out="identify-out")

Model text errors raise :class:`ModelError` (``file``, ``line``, ``column``);
a missing file raises ``FileNotFoundError``; a failed computation raises
:class:`PlantcError`; bad arguments raise ``ValueError``. Every call releases
the GIL and can be interrupted with Ctrl-C (``KeyboardInterrupt``).

Results of the identification workflows (:meth:`Model.compare`,
:meth:`Model.fit`, :meth:`Model.diagnose`, :meth:`Model.identify`) are the
JSON of the matching ``plantc ... --json`` command (the same code runs), as
:class:`Result` objects: ``r.fit.parameters["J1"].value`` or ``r["fit"]``;
``r.json`` is the plain dict.
"""

from __future__ import annotations

import glob as _glob
import html as _html
import json as _json
import os as _os
import shutil as _shutil
import tempfile as _tempfile
import weakref as _weakref
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Union

import numpy as _np

from . import _native
from ._native import ModelError, PlantcError

__all__ = [
    "Model",
    "ModelError",
    "PlantcError",
    "Result",
    "Equations",
    "Linearization",
    "Trajectory",
    "IdentifyResult",
    "lqr",
    "place",
    "cli",
]

Values = Optional[Mapping[str, float]]
Data = Union[str, "_os.PathLike[str]", Sequence[Any], Mapping[str, Any]]


class Result:
    """A JSON result with attribute access: ``r.key``, ``r["key"]``, ``r.json``."""

    def __init__(self, data: Mapping[str, Any]):
        object.__setattr__(self, "json", dict(data))

    @staticmethod
    def _wrap(v: Any) -> Any:
        if isinstance(v, dict):
            return Result(v)
        if isinstance(v, list):
            return [Result._wrap(x) for x in v]
        return v

    def __getattr__(self, name: str) -> Any:
        try:
            return Result._wrap(self.json[name])
        except KeyError:
            raise AttributeError(
                f"no field `{name}` (fields: {', '.join(self.json)})"
            ) from None

    def __getitem__(self, key: str) -> Any:
        return Result._wrap(self.json[key])

    def __contains__(self, key: str) -> bool:
        return key in self.json

    def keys(self):
        return self.json.keys()

    def items(self):
        return [(k, Result._wrap(v)) for k, v in self.json.items()]

    def __iter__(self):
        return iter(self.json)

    def __len__(self) -> int:
        return len(self.json)

    def __dir__(self):
        return list(self.json) + ["json", "keys", "items"]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(self.json)})"


def _check_names(mapping: Values, what: str) -> List[tuple]:
    if mapping is None:
        return []
    if not isinstance(mapping, Mapping):
        raise TypeError(f"{what} must be a dict of name -> number, got {type(mapping).__name__}")
    return [(str(k), float(v)) for k, v in mapping.items()]


def _rows(a: Any, what: str, square: bool = False) -> List[List[float]]:
    m = _np.asarray(a, dtype=float)
    if m.ndim == 1 and square:
        m = _np.diag(m)
    if m.ndim != 2:
        raise ValueError(f"{what} must be a matrix (2-D), got shape {m.shape}")
    return m.tolist()


class Equations(Result):
    """The equations of motion: the fields of ``plantc derive --json``
    (printed forms: ``mass_matrix``, ``bias``, ``forces``, ``input_matrix``,
    ``f``, ``g``, ``derived``) and ``latex`` with the same in LaTeX.
    :meth:`sympy` gives SymPy expressions when SymPy is installed."""

    def sympy(self) -> Dict[str, Any]:
        """The printed forms parsed by SymPy: a dict of the same keys
        (``mass_matrix``, ``bias``, ``forces``, ``input_matrix``, ``f``, ``g``)
        with SymPy expressions (a velocity ``q'`` becomes the symbol ``q_dot``)."""
        try:
            import sympy
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Equations.sympy() needs SymPy: pip install sympy") from e

        def conv(s: Optional[str]):
            if s is None:
                return None
            text = s.replace("^", "**")
            # q' -> q_dot (the printed velocity), q'' -> q_ddot
            import re

            text = re.sub(r"([A-Za-z_][A-Za-z_0-9]*)''", r"\1_ddot", text)
            text = re.sub(r"([A-Za-z_][A-Za-z_0-9]*)'", r"\1_dot", text)
            return sympy.sympify(text, locals=_sympy_locals(sympy))

        def walk(v):
            if isinstance(v, list):
                return [walk(x) for x in v]
            if isinstance(v, dict):
                return {k: walk(x) for k, x in v.items()}
            return conv(v)

        keys = ["mass_matrix", "bias", "forces", "input_matrix", "f", "g", "derived"]
        return {k: walk(self.json[k]) for k in keys if k in self.json}


def _sympy_locals(sympy) -> Dict[str, Any]:
    return {
        "sign": sympy.sign,
        "sat": sympy.Function("sat"),
        "dz": sympy.Function("dz"),
        "atan2": sympy.atan2,
        "abs": sympy.Abs,
        "S": sympy.Symbol("S"),
        "N": sympy.Symbol("N"),
        "E": sympy.Symbol("E"),
        "I": sympy.Symbol("I"),
        "Q": sympy.Symbol("Q"),
        "O": sympy.Symbol("O"),
        "beta": sympy.Symbol("beta"),
        "gamma": sympy.Symbol("gamma"),
        "lambda": sympy.Symbol("lambda"),
    }


class Linearization(Result):
    """``x' = A x + B u``, ``y = C x + D u`` about an operating point:
    numpy ``A``, ``B``, ``C``, ``D``, names ``state``, ``inputs``,
    ``outputs``, ``poles`` (complex numpy array) and the other fields of
    ``plantc linearize --json``."""

    @property
    def A(self) -> _np.ndarray:
        return _np.array(self.json["A"], dtype=float).reshape(len(self.json["state"]), -1)

    @property
    def B(self) -> _np.ndarray:
        return _np.array(self.json["B"], dtype=float).reshape(len(self.json["state"]), -1)

    @property
    def C(self) -> _np.ndarray:
        return _np.array(self.json["C"], dtype=float).reshape(len(self.json["outputs"]), -1)

    @property
    def D(self) -> _np.ndarray:
        return _np.array(self.json["D"], dtype=float).reshape(len(self.json["outputs"]), -1)

    @property
    def poles(self) -> _np.ndarray:
        return _np.array([complex(p["re"], p["im"]) for p in self.json["poles"]])


class Design(Result):
    """A state feedback ``u = -K x``: numpy ``K`` (and ``P`` for LQR),
    ``closed_loop_poles`` (complex numpy array), ``care_residual`` for LQR."""

    @property
    def K(self) -> _np.ndarray:
        return _np.array(self.json["K"], dtype=float)

    @property
    def P(self) -> _np.ndarray:
        return _np.array(self.json["P"], dtype=float)

    @property
    def closed_loop_poles(self) -> _np.ndarray:
        return _np.array([complex(p["re"], p["im"]) for p in self.json["closed_loop_poles"]])


class Trajectory(Result):
    """A simulation: numpy ``t`` (n,), ``states`` (n, states), ``inputs``
    (n, inputs), ``outputs`` (n, outputs) and their names; :meth:`to_pandas`
    gives a DataFrame with the columns of ``plantc sim``'s CSV."""

    def _matrix(self, key: str, names: str) -> _np.ndarray:
        return _np.array(self.json[key], dtype=float).reshape(len(self.json["t"]), len(self.json[names]))

    @property
    def t(self) -> _np.ndarray:
        return _np.array(self.json["t"], dtype=float)

    @property
    def states(self) -> _np.ndarray:
        return self._matrix("states", "state_names")

    @property
    def inputs(self) -> _np.ndarray:
        return self._matrix("inputs", "input_names")

    @property
    def outputs(self) -> _np.ndarray:
        return self._matrix("outputs", "output_names")

    def __getitem__(self, name: str) -> Any:
        """A column by name (a state, input or output), else a JSON field."""
        for key, names in (("states", "state_names"), ("inputs", "input_names"), ("outputs", "output_names")):
            if name in self.json[names]:
                return self._matrix(key, names)[:, self.json[names].index(name)]
        return super().__getitem__(name)

    def to_pandas(self):
        """A pandas DataFrame: ``t``, the states, the inputs, the outputs
        (``y_<name>`` when the name is a state's or input's), as ``plantc sim``'s CSV."""
        import pandas as pd

        cols: Dict[str, Any] = {"t": self.t}
        for i, n in enumerate(self.json["state_names"]):
            cols[n] = self.states[:, i]
        for i, n in enumerate(self.json["input_names"]):
            cols[n] = self.inputs[:, i]
        for i, n in enumerate(self.json["output_names"]):
            cols[n if n not in cols else f"y_{n}"] = self.outputs[:, i]
        if self.json["mode_names"]:
            cols["mode"] = [self.json["mode_names"][m] for m in self.json["modes"]]
        return pd.DataFrame(cols)


class IdentifyResult(Result):
    """The story of ``plantc identify`` (the fields of its ``report.json``:
    ``verdict``, ``effect``, ``rounds``, ``fit``, ``stages``, ...), ``out``
    the output directory, ``fitted`` the fitted model; in Jupyter it shows
    the before/after table and the figures."""

    def __init__(self, data: Mapping[str, Any], out: str):
        super().__init__(data)
        object.__setattr__(self, "out", out)

    @property
    def fitted(self) -> "Model":
        return Model.load(_os.path.join(self.out, "fitted.plant"))

    def table(self) -> List[Dict[str, Any]]:
        """The before/after table: one row per experiment and channel
        (``"RMSE, all channels"`` first), one column per stage (RMSE; fit % in
        ``"<stage> fit %"``)."""
        stages = self.json["stages"]
        rows: List[Dict[str, Any]] = [
            {"row": "RMSE, all channels", **{s["stage"]: s["report"]["rmse"] for s in stages}}
        ]
        first = stages[0]["report"]["experiments"]
        for i, e in enumerate(first):
            for ch in e["channels"]:
                name = e.get("name") or _os.path.splitext(_os.path.basename(e.get("file", f"experiment {i + 1}")))[0]
                row: Dict[str, Any] = {"row": f"{name} / {ch}"}
                for s in stages:
                    exps = s["report"]["experiments"]
                    c = exps[i]["channels"].get(ch) if i < len(exps) else None
                    row[s["stage"]] = None if c is None else c.get("rmse")
                    row[s["stage"] + " fit %"] = None if c is None else c.get("fit_percent")
                rows.append(row)
        return rows

    def _figures(self) -> List[str]:
        dirs = sorted(
            (d for d in _os.listdir(self.out) if _os.path.isdir(_os.path.join(self.out, d)) and d.split("-")[0].isdigit()),
            key=lambda d: int(d.split("-")[0]),
        )
        if not dirs:
            return []
        shown = [dirs[0], dirs[-1]] if len(dirs) > 1 else dirs
        return [f for d in shown for f in sorted(_glob.glob(_os.path.join(self.out, d, "*.svg")))]

    def _repr_html_(self) -> str:
        stages = [s["stage"] for s in self.json["stages"]]
        esc = _html.escape
        head = "".join(f"<th>{esc(s)}</th>" for s in stages)
        body = []
        for r in self.table():
            cells = []
            for s in stages:
                v = r.get(s)
                fit = r.get(s + " fit %")
                txt = "-" if v is None else f"{v:.3e}"
                if fit is not None:
                    txt = f"{fit:.1f} %&nbsp;&nbsp;{txt}"
                cells.append(f"<td style='text-align:right'>{txt}</td>")
            body.append(f"<tr><th style='text-align:left'>{esc(r['row'])}</th>{''.join(cells)}</tr>")
        effects = ", ".join(
            f"<code>{esc(r['effect'])}</code> on <code>{esc(r['target'])}</code>" for r in self.json.get("rounds", [])
        ) or "none"
        parts = [
            f"<p><b>plantc identify</b>: {esc(str(self.json.get('stop', '')))} "
            f"(verdict <code>{esc(self.json.get('verdict', ''))}</code>; effects: {effects})</p>",
            f"<table><tr><th></th>{head}</tr>{''.join(body)}</table>",
            "<p><small>cells: fit % (as MATLAB's compare) and RMSE in SI units, each stage's model simulated over the whole records</small></p>",
        ]
        params = self.json.get("fit", {}).get("parameters", {})
        if params:

            def num(x: Any, f: str) -> str:
                return "-" if x is None else format(x, f)

            rows = "".join(
                f"<tr><td><code>{esc(name)}</code></td><td>{num(p.get('value'), '.5e')}</td><td>{num(p.get('std_error'), '.1e')}</td></tr>"
                for name, p in params.items()
            )
            parts.append(f"<table><tr><th>parameter</th><th>value</th><th>std error</th></tr>{rows}</table>")
        for f in self._figures():
            with open(f, encoding="utf-8") as fh:
                svg = fh.read()
            rel = _os.path.relpath(f, self.out)
            parts.append(f"<figure>{svg}<figcaption>{esc(rel)}</figcaption></figure>")
        return "\n".join(parts)


def _run_cli(args: List[str]) -> Dict[str, Any]:
    code, out, err = _native.cli([str(a) for a in args])
    if code != 0:
        msg = err.strip() or out.strip()
        if msg.startswith("error: "):
            msg = msg[len("error: "):]
        if code == 2:
            raise ValueError(msg)
        raise PlantcError(msg)
    try:
        return _json.loads(out)
    except ValueError as e:  # pragma: no cover - a CLI bug
        raise PlantcError(f"plantc printed no JSON: {out[:200]!r}") from e


def cli(*args: str) -> tuple:
    """Run ``plantc ARGS...`` in process: ``(exit code, stdout, stderr)``."""
    return _native.cli([str(a) for a in args])


def _param_args(set: Optional[str], params: Values) -> List[str]:
    out: List[str] = []
    if set is not None:
        out += ["--set", set]
    for k, v in _check_names(params, "params"):
        out += ["--param", f"{k}={v!r}"]
    return out


class Model:
    """A plantc model (``*.plant``), checked when created."""

    def __init__(self, text: str, name: str, path: Optional[str], warnings: List[tuple]):
        self.text = text
        self.name = name
        self.path = path
        #: warnings and notes as (severity, code, message, line, column, help)
        self.warnings = warnings
        self._tmp: Optional[str] = None

    @classmethod
    def load(cls, path: Union[str, "_os.PathLike[str]"]) -> "Model":
        """Read and check a model file (``FileNotFoundError`` if missing,
        :class:`ModelError` with ``line`` and ``column`` if it has errors)."""
        p = _os.fspath(path)
        text, warnings = _native.load_file(p)
        return cls(text, p, p, warnings)

    @classmethod
    def from_text(cls, text: str, name: str = "<text>") -> "Model":
        """Check model text (:class:`ModelError` with ``line`` and ``column``
        if it has errors)."""
        if not isinstance(text, str):
            raise TypeError(f"model text must be a str, got {type(text).__name__}")
        warnings = _native.check_text(name, text)
        return cls(text, name, None, warnings)

    def __repr__(self) -> str:
        return f"Model({self.name!r})"

    def _file(self) -> str:
        """A file with the model text (the model's own, or a private copy)."""
        if self.path is not None:
            return self.path
        if self._tmp is None:
            d = _tempfile.mkdtemp(prefix="plantc-")
            _weakref.finalize(self, _shutil.rmtree, d, True)
            self._tmp = _os.path.join(d, "model.plant")
            with open(self._tmp, "w", encoding="utf-8") as f:
                f.write(self.text)
        return self._tmp

    # -- equations and linear design -------------------------------------

    def derive(self, expand: Optional[bool] = None) -> Equations:
        """The equations of motion (printed and LaTeX forms; ``expand``: True
        always expands ``f = M^-1 (...)``, False never, None as the CLI)."""
        return Equations(_json.loads(_native.derive(self.name, self.text, expand)))

    def linearize(self, set: Optional[str] = None, params: Values = None, at: Values = None) -> Linearization:
        """Numpy ``A, B, C, D`` about ``at`` (states and inputs by name, e.g.
        ``{"alpha": 0.1}``; others 0), with parameter set ``set`` and
        ``params`` overrides (SI)."""
        return Linearization(
            _json.loads(
                _native.linearize(self.name, self.text, set, _check_names(params, "params"), _check_names(at, "at"))
            )
        )

    def lqr(self, Q: Any, R: Any, set: Optional[str] = None, params: Values = None, at: Values = None) -> Design:
        """LQR on the linearization (``Q``, ``R`` matrices or their diagonals)."""
        lin = self.linearize(set=set, params=params, at=at)
        return lqr(lin.A, lin.B, Q, R)

    def place(self, poles: Sequence[complex], set: Optional[str] = None, params: Values = None, at: Values = None) -> Design:
        """Pole placement on the linearization (one input)."""
        lin = self.linearize(set=set, params=params, at=at)
        return place(lin.A, lin.B, poles)

    def analyze(
        self,
        output: Optional[str] = None,
        controller: Optional[str] = None,
        set: Optional[str] = None,
        params: Values = None,
    ) -> Result:
        """``plantc analyze --json``: Lie derivatives, relative degree, normal
        form and zero dynamics of ``output`` (or a controller's analysis)."""
        args = ["analyze", self._file(), "--json"] + _param_args(set, params)
        if output is not None:
            args += ["--output", output]
        if controller is not None:
            args += ["--controller", controller]
        return Result(_run_cli(args))

    def simulate(
        self,
        controller: str,
        x0: Values = None,
        duration: float = 10.0,
        set: Optional[str] = None,
        params: Values = None,
        gains: Values = None,
        output_rate: Optional[float] = None,
        sample_rate: Optional[float] = None,
    ) -> Trajectory:
        """Closed-loop simulation with one of the model's controllers from
        ``x0`` (states by name, radians; others 0), as ``plantc sim``."""
        return Trajectory(
            _json.loads(
                _native.simulate(
                    self.name,
                    self.text,
                    controller,
                    _check_names(x0, "x0"),
                    float(duration),
                    set,
                    _check_names(params, "params"),
                    _check_names(gains, "gains"),
                    None if output_rate is None else float(output_rate),
                    None if sample_rate is None else float(sample_rate),
                )
            )
        )

    # -- identification --------------------------------------------------

    def compare(self, data: Data, set: Optional[str] = None, params: Values = None, plots: Optional[str] = None, extra: Sequence[str] = ()) -> Result:
        """``plantc compare --json``: the model against measured data (CSV
        or MAT paths, a glob, or pandas DataFrames by name)."""
        with _DataFiles(data) as files:
            args = ["compare", self._file(), *files, "--json"] + _param_args(set, params)
            if plots is not None:
                args += ["--plots", _os.fspath(plots), "--force"]
            return Result(_run_cli(args + list(extra)))

    def fit(self, data: Data, out: Optional[str] = None, free: Optional[Sequence[str]] = None, force: bool = False, extra: Sequence[str] = ()) -> Result:
        """``plantc fit --json``: the ``estimate`` parameters (or ``free``)
        fitted to the data; ``out`` writes the fitted model there."""
        with _DataFiles(data) as files:
            args = ["fit", self._file(), *files, "--json"]
            if free:
                args += ["--free", ",".join(free)]
            if out is not None:
                args += ["-o", _os.fspath(out)]
            if force:
                args.append("--force")
            return Result(_run_cli(args + list(extra)))

    def diagnose(self, data: Data, extra: Sequence[str] = ()) -> Result:
        """``plantc diagnose --json``: which effect is missing."""
        with _DataFiles(data) as files:
            return Result(_run_cli(["diagnose", self._file(), *files, "--json"] + list(extra)))

    def identify(self, data: Data, out: Union[str, "_os.PathLike[str]"], max_effects: int = 3, force: bool = False, extra: Sequence[str] = ()) -> IdentifyResult:
        """``plantc identify``: nominal model -> where it fails -> missing
        effect -> fit -> again; writes ``out`` (fitted model, figures,
        ``report.json``) and returns the report."""
        out = _os.fspath(out)
        with _DataFiles(data) as files:
            args = ["identify", self._file(), *files, "-o", out, "--json", "--max-effects", str(int(max_effects))]
            if force:
                args.append("--force")
            return IdentifyResult(_run_cli(args + list(extra)), out)


class _DataFiles:
    """Measurement files for the CLI: paths (a glob pattern expanded), or
    DataFrames and numpy structured arrays written to a private directory
    as CSV with 17 significant digits (``{name: frame}``; the name becomes
    the experiment's)."""

    def __init__(self, data: Data):
        self.data = data
        self.tmp: Optional[str] = None

    def __enter__(self) -> List[str]:
        items: List[tuple] = []
        d = self.data
        if isinstance(d, Mapping):
            items = list(d.items())
        elif isinstance(d, (str, _os.PathLike)):
            items = [(None, d)]
        else:
            items = [(None, x) for x in d]
        files: List[str] = []
        for k, (name, x) in enumerate(items):
            if isinstance(x, (str, _os.PathLike)):
                p = _os.fspath(x)
                if any(c in p for c in "*?[") and not _os.path.exists(p):
                    found = sorted(_glob.glob(p))
                    if not found:
                        raise FileNotFoundError(2, "No file matches the pattern", p)
                    files += found
                    continue
                if not _os.path.exists(p):
                    raise FileNotFoundError(2, "No such file or directory", p)
                files.append(p)
            elif hasattr(x, "to_csv") and hasattr(x, "columns"):
                if self.tmp is None:
                    self.tmp = _tempfile.mkdtemp(prefix="plantc-data-")
                p = _os.path.join(self.tmp, f"{name if name is not None else f'experiment{k + 1}'}.csv")
                x.to_csv(p, index=False, float_format="%.17g")
                files.append(p)
            elif isinstance(x, _np.ndarray) and x.dtype.names:
                # a structured array: its field names are the columns
                if self.tmp is None:
                    self.tmp = _tempfile.mkdtemp(prefix="plantc-data-")
                p = _os.path.join(self.tmp, f"{name if name is not None else f'experiment{k + 1}'}.csv")
                cols = _np.column_stack([_np.asarray(x[n], dtype=float) for n in x.dtype.names])
                _np.savetxt(p, cols, delimiter=",", header=",".join(x.dtype.names), comments="", fmt="%.17g")
                files.append(p)
            else:
                raise TypeError(
                    "data: expected a path, a glob pattern, a pandas DataFrame or a numpy structured "
                    f"array (field names = columns), got {type(x).__name__}"
                    + (" without field names" if isinstance(x, _np.ndarray) else "")
                )
        if not files:
            raise ValueError("data: no files given")
        return files

    def __exit__(self, *exc) -> None:
        if self.tmp is not None:
            _shutil.rmtree(self.tmp, ignore_errors=True)


def lqr(A: Any, B: Any, Q: Any, R: Any) -> Design:
    """LQR ``u = -K x`` for ``x' = A x + B u`` (``Q``, ``R`` matrices or
    their diagonals); ``K``, ``P``, ``closed_loop_poles``, ``care_residual``."""
    return Design(
        _json.loads(_native.lqr(_rows(A, "A"), _rows(B, "B"), _rows(Q, "Q", True), _rows(R, "R", True)))
    )


def place(A: Any, B: Any, poles: Sequence[complex]) -> Design:
    """Pole placement ``u = -K x`` (one input) for the desired ``poles``."""
    ps = [(complex(p).real, complex(p).imag) for p in poles]
    return Design(_json.loads(_native.place(_rows(A, "A"), _rows(B, "B"), ps)))
