"""Identified models: the ``model.json`` written by ``ilcdob identify``, as a Python object.

:func:`load_model` reads the file into an :class:`IdentifiedModel`: the continuous-time
transfer function ``num(s)/den(s)`` (s-polynomials, highest power first; input commanded
acceleration in m/s^2, output position in m), its input delay (s), the model structure and
parameters with their covariance, the fits and the sample time of the data. From it,
:meth:`IdentifiedModel.plant_spec` and :meth:`IdentifiedModel.identification_spec` give the
specs of a fleet system, whose Delta set is then defined by the covariance
(:func:`ilcdob.design.delta_set`). A fleet file refers to such a file with
``plant = { model = "uav4.json" }`` (see :mod:`ilcdob.fleet`).

Only the keys listed in :data:`REQUIRED_KEYS` (and, when present, ``fit_percent``,
``noise_variance`` and ``signals``) are read; any other key is ignored, so model files with
more information load unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .display import html_table, polynomial_text
from .errors import ModelFileError, SpecError
from .inputs import read_json
from .uncertainty import ModelStructure
from .specs import (DOBSpec, IdentificationSpec, NoiseSpec, PIDSpec, PlantSpec, SystemSpec, UncertaintySpec,
                    as_polynomial, check_covariance)

if TYPE_CHECKING:
    import control as ct


__all__ = ["IdentifiedModel", "load_model", "model_from_dict", "REQUIRED_KEYS"]

#: Keys every model file must hold.
REQUIRED_KEYS = ("num", "den", "delay", "structure", "parameters", "covariance", "delay_estimated", "sample_time")

#: Relative tolerance of the check that ``num``/``den`` are the polynomials of ``parameters``.
CONSISTENCY_RTOL = 1e-6


def _number(name: str, value: Any, *, optional: bool = False) -> float:
    if optional and value is None:
        return float("nan")
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SpecError(f"`{name}`: got {value!r}, expected a number")
    return float(value)


def _count(name: str, value: Any, minimum: int) -> int:
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating)) \
        and float(value).is_integer() and value >= minimum
    if not ok:
        raise SpecError(f"`{name}`: got {value!r}, expected an integer >= {minimum}")
    return int(value)


def _vector(name: str, value: Any) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple, np.ndarray)) or any(isinstance(v, bool) for v in value):
        raise SpecError(f"`{name}`: got {value!r}, expected a list of numbers")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"`{name}`: got {value!r}, expected a list of numbers") from None
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise SpecError(f"`{name}`: got {value!r}, expected a 1-D list of finite numbers")
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class IdentifiedModel:
    """A continuous-time transfer-function model fitted to flight data.

    ``P(s) = num(s)/den(s) * exp(-delay*s)`` with ``den(s) = s^K A(s)``, ``A`` monic of
    degree ``poles - integrators``, and ``parameters = (a_{n-1}..a_0, b_m..b_0)`` (see
    ``ilcdob.uncertainty.ModelStructure``). Build with :func:`load_model` or
    :func:`model_from_dict`.

    Attributes
    ----------
    num, den : tuple of float
        s-polynomials, highest power first (input m/s^2, output m).
    delay : float
        Input delay, s (>= 0).
    poles, zeros, integrators : int
        Model structure (poles include the ``integrators`` fixed at s = 0).
    parameters : tuple of float
        Free denominator coefficients, then the numerator.
    covariance : tuple of tuple of float
        Covariance of ``parameters`` and, as last row/column when ``delay_estimated``, of
        the delay (s^2).
    delay_estimated : bool
        Whether the delay was estimated (then it has a variance) or fixed.
    sample_time : float
        Sample time of the identification data, s.
    fit_estimation, fit_validation : float
        Fit in % (``100 (1 - ||y - yhat|| / ||y - mean(y)||)``) on estimation and held-out
        data; NaN when not reported.
    noise_variance : float
        Residual variance of the estimation data, m^2 (NaN when not reported).
    input, output : str
        Names of the fitted signals ("" when not reported).
    source : str
        The file the model was read from, for messages.

    Raises
    ------
    SpecError
        A value is invalid or ``num``/``den`` are not the polynomials of ``parameters``;
        the message names the field and the value.
    """

    num: tuple[float, ...]
    den: tuple[float, ...]
    delay: float
    poles: int
    zeros: int
    integrators: int
    parameters: tuple[float, ...]
    covariance: tuple[tuple[float, ...], ...]
    delay_estimated: bool
    sample_time: float
    fit_estimation: float = float("nan")
    fit_validation: float = float("nan")
    noise_variance: float = float("nan")
    input: str = ""
    output: str = ""
    source: str = "<memory>"

    def __post_init__(self) -> None:
        num, den = as_polynomial(self.num, "num"), as_polynomial(self.den, "den")
        if len(num) >= len(den):
            raise SpecError(f"`num`/`den`: the model must be strictly proper (deg num < deg den), got "
                            f"num = {list(num)}, den = {list(den)}")
        delay = _number("delay", self.delay)
        if not (math.isfinite(delay) and delay >= 0):
            raise SpecError(f"`delay`: got {self.delay!r}, expected a finite number >= 0 (s)")
        poles = _count("structure.poles", self.poles, 1)
        zeros = _count("structure.zeros", self.zeros, 0)
        integrators = _count("structure.integrators", self.integrators, 0)
        if zeros >= poles or integrators > poles:
            raise SpecError(f"`structure`: got poles = {poles}, zeros = {zeros}, integrators = {integrators}; "
                            "expected zeros < poles and integrators <= poles")
        params = _vector("parameters", self.parameters)
        n_free = poles - integrators
        if len(params) != n_free + zeros + 1:
            raise SpecError(f"`parameters`: got {len(params)} values {list(params)}; the structure (poles = {poles}, "
                            f"zeros = {zeros}, integrators = {integrators}) has {n_free + zeros + 1}")
        if not isinstance(self.delay_estimated, (bool, np.bool_)):
            raise SpecError(f"`delay_estimated`: got {self.delay_estimated!r}, expected true or false")
        n_cov = len(params) + (1 if self.delay_estimated else 0)
        try:
            cov = np.asarray(self.covariance, dtype=float)
        except (TypeError, ValueError):
            raise SpecError(f"`covariance`: got {self.covariance!r}, expected a {n_cov} x {n_cov} matrix "
                            "(list of rows)") from None
        if cov.shape != (n_cov, n_cov) or not np.all(np.isfinite(cov)):
            what = "parameters and the delay" if self.delay_estimated else "parameters"
            raise SpecError(f"`covariance`: got shape {cov.shape}, expected a finite {n_cov} x {n_cov} matrix "
                            f"(covariance of the {len(params)} {what})")
        check_covariance(cov, n_cov, "covariance")  # symmetric positive semi-definite
        ts = _number("sample_time", self.sample_time)
        if not (math.isfinite(ts) and ts > 0):
            raise SpecError(f"`sample_time`: got {self.sample_time!r}, expected a number > 0 (s)")
        # num/den must be the polynomials of the parameters: the Delta set is drawn around them
        exp_den = np.concatenate([[1.0], params[:n_free], np.zeros(integrators)])
        exp_num = np.asarray(params[n_free:])
        got_den, got_num = np.asarray(den) / den[0], np.asarray(num) / den[0]
        got_num = np.concatenate([np.zeros(max(0, exp_num.size - got_num.size)), got_num])
        scale = max(np.max(np.abs(exp_den)), np.max(np.abs(exp_num)), 1e-300)
        same = got_den.size == exp_den.size and got_num.size == exp_num.size and \
            np.allclose(got_den, exp_den, rtol=CONSISTENCY_RTOL, atol=CONSISTENCY_RTOL * scale) and \
            np.allclose(got_num, exp_num, rtol=CONSISTENCY_RTOL, atol=CONSISTENCY_RTOL * scale)
        if not same:
            raise SpecError(f"`num`/`den`: got num = {list(num)}, den = {list(den)}, but `parameters` = {list(params)} "
                            f"with poles = {poles}, zeros = {zeros}, integrators = {integrators} give num = "
                            f"{exp_num.tolist()}, den = {exp_den.tolist()}")
        for name in ("input", "output", "source"):
            if not isinstance(getattr(self, name), str):
                raise SpecError(f"`{name}`: got {getattr(self, name)!r}, expected a string")
        object.__setattr__(self, "num", num)
        object.__setattr__(self, "den", den)
        object.__setattr__(self, "delay", delay)
        object.__setattr__(self, "poles", poles)
        object.__setattr__(self, "zeros", zeros)
        object.__setattr__(self, "integrators", integrators)
        object.__setattr__(self, "parameters", params)
        object.__setattr__(self, "covariance", tuple(tuple(float(v) for v in row) for row in cov))
        object.__setattr__(self, "delay_estimated", bool(self.delay_estimated))
        object.__setattr__(self, "sample_time", ts)
        for name in ("fit_estimation", "fit_validation", "noise_variance"):
            object.__setattr__(self, name, _number(name, getattr(self, name), optional=True))

    def __repr__(self) -> str:
        delay = f" exp(-{self.delay:.4g} s)" if self.delay else ""
        held = "" if math.isnan(self.fit_validation) else f", held-out {self.fit_validation:.1f} %"
        source = self.source if len(self.source) <= 40 else "..." + self.source[-37:]
        return (f"<IdentifiedModel {source!r}: G(s) = ({polynomial_text(self.num, 4)}) / "
                f"({polynomial_text(self.den, 4)}){delay}; Ts {self.sample_time:g} s{held}>")

    def _repr_html_(self) -> str:
        names = self.structure.parameter_names + (["delay (s)"] if self.delay_estimated else [])
        values = [*self.parameters, *([self.delay] if self.delay_estimated else [])]
        rows = [[n, float(v), float(e)] for n, v, e in zip(names, values, self.std)]
        rows += [["fit estimation (%)", self.fit_estimation, ""], ["fit held-out (%)", self.fit_validation, ""],
                 ["sample time (s)", self.sample_time, ""]]
        delay = f" exp(-{self.delay:.4g} s)" if self.delay else ""
        return html_table(f"{self.source}: G(s) = ({polynomial_text(self.num, 4)}) / ({polynomial_text(self.den, 4)})"
                          f"{delay}", ["", "value", "1 sigma"], rows)

    @property
    def transfer_function(self) -> ct.TransferFunction:
        """``num(s)/den(s)`` as a continuous-time python-control system, its signals named.

        Same convention as ``TFEstimate.model`` of :mod:`ilcdob.identification`:
        ``inputs``/``outputs`` are :attr:`input` and :attr:`output`, each ``.`` replaced by
        ``_`` (python-control reserves ``.`` for ``system.signal``); when a name was not
        reported (""), python-control's default (``u[0]``, ``y[0]``) is kept. The system is
        named after the stem of :attr:`source` (``uav4.json`` -> ``uav4``, ``.`` replaced by
        ``_``), or python-control's default for a model built in memory. The input delay is
        not part of the dynamics (python-control has no delay; no Pade approximation is
        made): it is attached as the attribute ``input_delay`` (s, equal to :attr:`delay`),
        so the model is ``G(jw) exp(-jw input_delay)``; any operation on the object (series,
        feedback, sampling) drops it.
        """
        def label(text: str) -> list[str] | None:
            return [text.replace(".", "_")] if text else None

        import control as ct

        name = None if self.source == "<memory>" else Path(self.source).stem.replace(".", "_") or None
        sys = ct.tf(list(self.num), list(self.den), inputs=label(self.input), outputs=label(self.output), name=name)
        sys.input_delay = self.delay
        return sys

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of ``parameters`` (and of the delay, last, when estimated)."""
        return np.sqrt(np.clip(np.diag(np.asarray(self.covariance)), 0.0, None))

    @property
    def structure(self) -> ModelStructure:
        """The model structure as ``ilcdob.uncertainty.ModelStructure``."""
        return ModelStructure(self.poles, self.zeros, self.integrators)

    def plant_spec(self) -> PlantSpec:
        """The plant ``num/den * exp(-delay s)`` as a :class:`~ilcdob.specs.PlantSpec`."""
        return PlantSpec(self.num, self.den, self.delay)

    def identification_spec(self, source: str | None = None) -> IdentificationSpec:
        """Structure, parameters, covariance and fits as an :class:`~ilcdob.specs.IdentificationSpec`.

        Parameters
        ----------
        source : str, optional
            What to record as the origin (default: :attr:`source`).
        """
        return IdentificationSpec(self.poles, self.zeros, self.integrators, self.parameters, self.covariance,
                                  self.delay_estimated, self.fit_estimation, self.fit_validation,
                                  self.source if source is None else source)

    def system_spec(self, name: str, controller: PIDSpec, dob: DOBSpec, *, noise: NoiseSpec | None = None,
                    uncertainty: UncertaintySpec | None = None) -> SystemSpec:
        """A fleet system flying this model, its Delta set defined by the covariance.

        Parameters
        ----------
        name : str
            System name (unique in its fleet).
        controller : PIDSpec
        dob : DOBSpec
        noise : NoiseSpec, optional
            The system's own process noise (default: none).
        uncertainty : UncertaintySpec, optional
            A stated bound, which takes precedence over the covariance for the Delta set.
        """
        return SystemSpec(name=name, plant=self.plant_spec(), controller=controller, dob=dob,
                          noise=noise if noise is not None else NoiseSpec(),
                          identification=self.identification_spec(), uncertainty=uncertainty)


def model_from_dict(data: Any, source: str = "<memory>") -> IdentifiedModel:
    """Validate the parsed content of a model file (see :func:`load_model`).

    Parameters
    ----------
    data : dict
        The parsed JSON object (keys: :data:`REQUIRED_KEYS`, optionally ``fit_percent``,
        ``noise_variance`` and ``signals``).
    source : str
        Where it came from, for messages and the model's ``source``.

    Returns
    -------
    IdentifiedModel
        The checked model.

    Raises
    ------
    ModelFileError
        A required key is missing or a value is invalid; the message names ``source``, the
        key and the value.
    """
    if not isinstance(data, dict):
        raise ModelFileError(f"{source}: expected a JSON object with keys {list(REQUIRED_KEYS)}, got "
                             f"{type(data).__name__}")
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise ModelFileError(f"{source}: missing key(s) {missing}; a model file of `ilcdob identify` holds "
                             f"{list(REQUIRED_KEYS)}")
    structure = data["structure"]
    if not isinstance(structure, dict) or any(k not in structure for k in ("poles", "zeros", "integrators")):
        raise ModelFileError(f"{source}: `structure`: got {structure!r}, expected an object with keys poles, "
                             "zeros, integrators")
    fits = data.get("fit_percent", {})
    if not isinstance(fits, dict):
        raise ModelFileError(f"{source}: `fit_percent`: got {fits!r}, expected an object with keys estimation, "
                             "validation")
    signals = data.get("signals", {})
    if not isinstance(signals, dict):
        raise ModelFileError(f"{source}: `signals`: got {signals!r}, expected an object with keys input, output")
    try:
        return IdentifiedModel(
            num=_vector("num", data["num"]), den=_vector("den", data["den"]), delay=data["delay"],
            poles=structure["poles"], zeros=structure["zeros"], integrators=structure["integrators"],
            parameters=data["parameters"], covariance=data["covariance"], delay_estimated=data["delay_estimated"],
            sample_time=data["sample_time"], fit_estimation=fits.get("estimation"),
            fit_validation=fits.get("validation"), noise_variance=data.get("noise_variance"),
            input=str(signals.get("input", "")), output=str(signals.get("output", "")), source=source)
    except SpecError as exc:
        raise ModelFileError(f"{source}: {exc}") from exc


def load_model(path: str | Path) -> IdentifiedModel:
    """Read a ``model.json`` written by ``ilcdob identify`` (``TFEstimate.to_dict``).

    Parameters
    ----------
    path : str or pathlib.Path

    Returns
    -------
    IdentifiedModel

    Raises
    ------
    ModelFileError
        The file cannot be read, is not a regular file (a FIFO, a device), is larger than
        :data:`ilcdob.inputs.MAX_DOCUMENT_BYTES`, is not JSON (or holds a number beyond float
        range or a nesting deeper than :data:`ilcdob.inputs.MAX_NESTING`), misses a key of
        :data:`REQUIRED_KEYS`, or holds an invalid value; the message names the file, the key
        and the value.
    """
    path = Path(path)
    data = read_json(path, "model file", error=ModelFileError,
                     hint="a model file is the model.json of `ilcdob identify`")
    return model_from_dict(data, str(path))
