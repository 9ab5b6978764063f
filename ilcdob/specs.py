"""Configuration dataclasses of one system: plant, PID, DOB and its own noise.

Units: time in s, position in m, acceleration in m/s^2, frequency in Hz unless a field
says rad/s. Transfer functions are continuous-time polynomials in s, highest power first;
a plant may also be given as a python-control ``TransferFunction`` or ``StateSpace``
(continuous-time, SISO, strictly proper; see :meth:`PlantSpec.from_lti`).
All dataclasses are frozen and validated in ``__post_init__``; a bad value raises
:class:`~ilcdob.errors.SpecError` naming the field, the value and what is valid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from sys import modules as _modules
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import SpecError
from .names import check_name
from .uncertainty import ModelStructure, multiplicative_bound

if TYPE_CHECKING:
    import control as ct

__all__ = ["PlantSpec", "PIDSpec", "DOBSpec", "NoiseSpec", "IdentificationSpec", "UncertaintySpec", "LimitSpec",
           "SensorSpec", "SystemSpec", "GRAVITY", "check_noise_std",
           "LTI_NUMERATOR_RTOL", "MAX_NOISE_AMPLITUDE", "COVARIANCE_RTOL", "as_polynomial", "check_covariance"]

#: Largest process-noise amplitude a fleet may state, m/s^2 (about 100 g: far beyond any vehicle).
MAX_NOISE_AMPLITUDE = 1e3

#: Standard gravity, m/s^2 (the tilt and thrust limits of :class:`LimitSpec`).
GRAVITY = 9.80665

#: Relative tolerance (of the largest entry) of the symmetry and positive-semi-definiteness
#: checks of a covariance matrix: files store 10 significant digits, so the two triangles of
#: a symmetric matrix may differ in the last one.
COVARIANCE_RTOL = 1e-6


def _is_lti(value: Any) -> bool:
    """Whether ``value`` is a python-control system; python-control is not imported for the question (an LTI
    object exists only once its caller has imported it)."""
    ct = _modules.get("control")
    return ct is not None and isinstance(value, ct.LTI)


def _real(name: str, value: object) -> float:
    """``value`` as a float; SpecError naming ``name`` for text, booleans and other non-numbers."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise SpecError(f"`{name}`: got {value!r}, expected a number")
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise SpecError(f"`{name}`: got {value!r}, expected a number") from None


def check_covariance(value: object, n: int, name: str = "covariance") -> np.ndarray:
    """A covariance matrix checked to be a finite, symmetric, positive semi-definite n x n matrix.

    Parameters
    ----------
    value : array_like
        The matrix (list of rows).
    n : int
        Its expected size.
    name : str
        What it is, for the message.

    Returns
    -------
    numpy.ndarray
        The matrix as given (not symmetrised).

    Raises
    ------
    SpecError
        Not numbers, the wrong shape, non-finite, not symmetric or with a negative
        eigenvalue (both up to :data:`COVARIANCE_RTOL` of the largest entry).
    """
    try:
        cov = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"`{name}`: got {value!r}, expected a {n} x {n} matrix (list of rows)") from None
    if cov.shape != (n, n) or not np.all(np.isfinite(cov)):
        raise SpecError(f"`{name}`: expected a finite {n} x {n} matrix, got shape {cov.shape}"
                        + ("" if cov.shape != (n, n) else f" with non-finite entries {cov.tolist()}"))
    tol = COVARIANCE_RTOL * float(np.max(np.abs(cov), initial=0.0))
    asym = float(np.max(np.abs(cov - cov.T), initial=0.0))
    if asym > tol:
        raise SpecError(f"`{name}`: not symmetric (largest |C - C^T| entry {asym:.3g}, got {cov.tolist()}); a "
                        "covariance must be a symmetric positive semi-definite matrix")
    low = float(np.min(np.linalg.eigvalsh((cov + cov.T) / 2), initial=0.0)) if n else 0.0
    if low < -tol:
        raise SpecError(f"`{name}`: has a negative eigenvalue {low:.3g} (got {cov.tolist()}); a covariance must "
                        "be a symmetric positive semi-definite matrix")
    return cov


def as_polynomial(values: object, name: str) -> tuple[float, ...]:
    """Checked polynomial coefficients, highest power first, leading zeros dropped.

    Parameters
    ----------
    values : array_like
        The coefficients (a number or a 1-D list of numbers).
    name : str
        What they are (e.g. ``"plant.num"``), for the error message.

    Returns
    -------
    tuple of float
        The coefficients from the first non-zero one on (``-0.0`` written as ``0.0``).

    Raises
    ------
    SpecError
        Not numbers, not 1-D, empty, not finite, or all zero.
    """
    try:
        arr = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError) as exc:
        raise SpecError(f"`{name}`: expected a list of numbers, got {values!r}") from exc
    if arr.ndim != 1 or arr.size == 0:
        raise SpecError(f"`{name}`: expected a non-empty 1-D list of numbers, got {values!r}")
    if not np.all(np.isfinite(arr)):
        raise SpecError(f"`{name}`: coefficients must be finite, got {values!r}")
    nz = np.flatnonzero(arr)
    if nz.size == 0:
        raise SpecError(f"`{name}`: polynomial is identically zero ({values!r})")
    return tuple(float(v) + 0.0 for v in arr[nz[0]:])  # + 0.0: no -0.0 in files and messages


def _vector(values: object, name: str) -> tuple[float, ...]:
    """Finite numbers of a 1-D list; SpecError naming ``name`` otherwise."""
    if isinstance(values, (str, bytes)):
        raise SpecError(f"`{name}`: got {values!r}, expected a list of numbers")
    try:
        arr = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        raise SpecError(f"`{name}`: got {values!r}, expected a list of numbers") from None
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise SpecError(f"`{name}`: got {values!r}, expected a 1-D list of finite numbers")
    return tuple(float(v) for v in arr)


#: Leading numerator coefficients of a StateSpace converted to a transfer function that are
#: below this fraction of the largest numerator coefficient are conversion roundoff (the
#: Markov parameters ``C A^k B`` that are zero), and are dropped.
LTI_NUMERATOR_RTOL = 1e-10


def _lti_description(sys: Any) -> str:
    kind = type(sys).__name__
    try:
        return f"{kind} with {sys.ninputs} input(s), {sys.noutputs} output(s), dt = {sys.dt!r}"
    except AttributeError:
        return kind


def _lti_polys(sys: Any) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of a continuous-time SISO strictly proper python-control system."""
    import control as ct

    if not isinstance(sys, (ct.TransferFunction, ct.StateSpace)):
        raise SpecError(f"`plant`: got a {_lti_description(sys)}; expected a python-control TransferFunction or "
                        "StateSpace, or num and den polynomials")
    if sys.ninputs != 1 or sys.noutputs != 1:
        raise SpecError(f"`plant`: got a {_lti_description(sys)}; expected a SISO system (input: commanded "
                        "acceleration, m/s^2; output: position, m)")
    if not sys.isctime():
        raise SpecError(f"`plant`: got a discrete-time {_lti_description(sys)}; expected a continuous-time "
                        "system (dt = 0): ilcdob discretises the plant itself at the fleet's sample time")
    if isinstance(sys, ct.StateSpace):
        d = float(np.asarray(sys.D, dtype=float).ravel()[0])
        if d != 0.0:
            raise SpecError(f"`plant`: got a {_lti_description(sys)} and D = {d!r}; the plant must be "
                            "strictly proper (D = 0)")
        if sys.nstates == 0:
            raise SpecError(f"`plant`: got a {_lti_description(sys)} without states and D = 0: the transfer "
                            "function is identically zero")
        tf = ct.tf(sys)
        num = np.asarray(tf.num[0][0], dtype=float)
        den = np.asarray(tf.den[0][0], dtype=float)
        big = np.abs(num) > LTI_NUMERATOR_RTOL * np.max(np.abs(num), initial=0.0)
        if np.any(big):
            num = num[np.flatnonzero(big)[0]:]
        return num, den
    return np.asarray(sys.num[0][0], dtype=float), np.asarray(sys.den[0][0], dtype=float)


def _positive(name: str, value: float, *, allow_zero: bool = False) -> None:
    ok = math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    if not ok:
        valid = "a finite number >= 0" if allow_zero else "a finite number > 0"
        raise SpecError(f"`{name}`: got {value!r}, expected {valid}")


@dataclass(frozen=True)
class PlantSpec:
    """Continuous-time plant ``P(s) = num(s)/den(s) * exp(-delay*s)``.

    ``PlantSpec(num, den, delay)`` takes the polynomials; ``PlantSpec(sys, delay=...)`` or
    :meth:`from_lti` takes a python-control ``TransferFunction`` or ``StateSpace``
    (continuous-time, SISO, strictly proper; python-control has no delay, so it is given
    separately). Either way the fields hold the polynomials.

    Attributes
    ----------
    num, den : tuple of float
        Polynomial coefficients in s, highest power first. Input: commanded acceleration
        (m/s^2); output: position (m).
    delay : float
        Input delay in s (>= 0).

    Raises
    ------
    SpecError
        Non-finite or empty polynomials, a negative delay, an improper plant, or a
        python-control system that is discrete-time, MIMO or improper (the message names it).
    """

    num: tuple[float, ...]
    den: tuple[float, ...] = ()
    delay: float = 0.0

    def __post_init__(self) -> None:
        if _is_lti(self.num):
            den_given = not (isinstance(self.den, tuple) and len(self.den) == 0)
            if den_given:
                raise SpecError(f"`plant.den`: got {self.den!r} together with a python-control system as `num`; "
                                "give either the system alone or the num and den polynomials")
            num, den = _lti_polys(self.num)
            object.__setattr__(self, "num", num)
            object.__setattr__(self, "den", den)
        elif isinstance(self.den, tuple) and len(self.den) == 0:
            raise SpecError(f"`plant.den`: missing (num = {self.num!r}); give num and den polynomials, or a "
                            "python-control TransferFunction or StateSpace alone")
        object.__setattr__(self, "num", as_polynomial(self.num, "plant.num"))
        object.__setattr__(self, "den", as_polynomial(self.den, "plant.den"))
        object.__setattr__(self, "delay", _real("plant.delay", self.delay))
        _positive("plant.delay", self.delay, allow_zero=True)
        if len(self.num) >= len(self.den):
            raise SpecError(
                f"`plant`: must be strictly proper (deg num < deg den), got num={list(self.num)}, "
                f"den={list(self.den)}"
            )

    @classmethod
    def from_lti(cls, sys: ct.TransferFunction | ct.StateSpace, delay: float = 0.0) -> "PlantSpec":
        """The plant ``sys(s) * exp(-delay*s)`` from a python-control system.

        Parameters
        ----------
        sys : control.TransferFunction or control.StateSpace
            Continuous-time (``dt = 0``), SISO, strictly proper. A ``StateSpace`` must have
            ``D = 0``; it is converted with ``control.tf`` and leading numerator coefficients
            below ``LTI_NUMERATOR_RTOL`` times the largest one (conversion roundoff) are dropped.
        delay : float
            Input delay, s (>= 0).

        Raises
        ------
        SpecError
            ``sys`` is not a TransferFunction/StateSpace, is discrete-time, MIMO or not
            strictly proper, or ``delay`` is negative.
        """
        if not _is_lti(sys):
            raise SpecError(f"`plant`: got {type(sys).__name__} {sys!r}; expected a python-control "
                            "TransferFunction or StateSpace")
        return cls(sys, delay=delay)

    @property
    def transfer_function(self) -> ct.TransferFunction:
        """``num(s)/den(s)`` as a python-control transfer function (without the delay)."""
        import control as ct

        return ct.tf(list(self.num), list(self.den))

    @property
    def relative_degree(self) -> int:
        """Continuous relative degree, deg(den) - deg(num)."""
        return len(self.den) - len(self.num)


@dataclass(frozen=True)
class PIDSpec:
    """Outer-loop PID ``C(s) = kp + ki/s + kd*s/(derivative_filter*s + 1)``.

    With ``acceleration_feedforward`` the controller also adds the reference acceleration
    ``a_ff = d^2 r/dt^2`` of the trajectory setpoint to its output, as flight stacks do
    (PX4's position controller feeds the setpoint acceleration forward). It enters the loop
    exactly like ``-d_f``, so the maps of :mod:`ilcdob.loop` are unchanged. Without it, a
    learning signal built from another vehicle's error also has to carry the trajectory's
    acceleration, and both tracking and disturbance estimates degrade on curved paths.

    Attributes
    ----------
    kp : float
        Proportional gain, (m/s^2)/m = 1/s^2.
    ki : float
        Integral gain, 1/s^3 (>= 0).
    kd : float
        Derivative gain, 1/s (>= 0).
    derivative_filter : float
        Time constant of the derivative low-pass, s (> 0).
    acceleration_feedforward : bool
        Add the reference acceleration to the controller output (default True).
    """

    kp: float
    ki: float
    kd: float
    derivative_filter: float
    acceleration_feedforward: bool = True

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd", "derivative_filter"):
            object.__setattr__(self, name, _real(f"controller.{name}", getattr(self, name)))
        _positive("controller.kp", self.kp)
        _positive("controller.ki", self.ki, allow_zero=True)
        _positive("controller.kd", self.kd, allow_zero=True)
        _positive("controller.derivative_filter", self.derivative_filter)
        if not isinstance(self.acceleration_feedforward, bool):
            raise SpecError(f"`controller.acceleration_feedforward`: got {self.acceleration_feedforward!r}, "
                            "expected true or false")


#: Highest order of a DOB's low-pass Q (:class:`DOBSpec`).
MAX_Q_ORDER = 20


@dataclass(frozen=True)
class DOBSpec:
    """Disturbance observer low-pass ``Q(s) = 1/(q_time_constant*s + 1)**q_order``.

    Attributes
    ----------
    q_order : int
        Order of Q, 1 to :data:`MAX_Q_ORDER`; must be >= the relative degree of the plant model
        so that ``M = Q/P_hat`` is proper.
    q_time_constant : float
        Time constant in s (> 0); the DOB bandwidth is about 1/q_time_constant rad/s.
    """

    q_order: int
    q_time_constant: float

    def __post_init__(self) -> None:
        if isinstance(self.q_order, (bool, str, bytes)) or not isinstance(self.q_order, (int, float, np.number)) \
                or not float(self.q_order).is_integer() or self.q_order < 1:
            raise SpecError(f"`dob.q_order`: got {self.q_order!r}, expected an integer >= 1")
        if self.q_order > MAX_Q_ORDER:
            raise SpecError(f"`dob.q_order`: got {self.q_order!r}, expected 1 to {MAX_Q_ORDER}: each order is a state "
                            "of Q and of M = Q/P_hat in every loop built (measured: a fleet check takes 2.3 s at 20, "
                            "9.6 s at 100; a DOB's Q is of order 2 to 4)")
        object.__setattr__(self, "q_order", int(self.q_order))
        object.__setattr__(self, "q_time_constant", _real("dob.q_time_constant", self.q_time_constant))
        _positive("dob.q_time_constant", self.q_time_constant)


@dataclass(frozen=True)
class NoiseSpec:
    """The system's own small sinusoidal process noise, added to the disturbance.

    ``n(t) = amplitude * sin(2*pi*frequency*t + phase)`` in m/s^2 at the plant input
    (paper Sec. IV, docs/theory.md section 4: every system gets its own noise of higher
    frequency).

    Attributes
    ----------
    amplitude : float
        m/s^2, 0 to :data:`MAX_NOISE_AMPLITUDE` (default 0: no noise).
    frequency : float
        Hz, > 0.
    phase : float
        rad.
    """

    amplitude: float = 0.0
    frequency: float = 2.0
    phase: float = 0.0

    def __post_init__(self) -> None:
        for name in ("amplitude", "frequency", "phase"):
            object.__setattr__(self, name, _real(f"noise.{name}", getattr(self, name)))
        _positive("noise.amplitude", self.amplitude, allow_zero=True)
        if self.amplitude > MAX_NOISE_AMPLITUDE:
            raise SpecError(f"`noise.amplitude`: got {self.amplitude!r}, expected 0 to {MAX_NOISE_AMPLITUDE:g} m/s^2 "
                            "(the process noise at the plant input, an acceleration)")
        _positive("noise.frequency", self.frequency)
        if not math.isfinite(self.phase):
            raise SpecError(f"`noise.phase`: got {self.phase!r}, expected a finite number (rad)")

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Noise samples at given times.

        Parameters
        ----------
        t : array_like
            Times, s.

        Returns
        -------
        numpy.ndarray
            ``n(t)``, m/s^2.
        """
        return self.amplitude * np.sin(2.0 * np.pi * self.frequency * np.asarray(t) + self.phase)


@dataclass(frozen=True)
class UncertaintySpec:
    """A multiplicative model-error bound stated in the fleet file: ``|Delta(jw)| <= bound``.

    It defines the system's Delta set (:func:`ilcdob.design.delta_set`) when given, ahead of
    an identification's covariance (docs/theory.md section 3).

    Attributes
    ----------
    bound : float
        Relative model error, in (0, 1).
    """

    bound: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "bound", _real("uncertainty.bound", self.bound))
        if not (math.isfinite(self.bound) and 0 < self.bound < 1):
            raise SpecError(f"`uncertainty.bound`: got {self.bound!r}, expected a relative error in (0, 1)")


@dataclass(frozen=True)
class IdentificationSpec:
    """Where a plant model came from, when it was identified (``ilcdob identify``).

    The parameter covariance defines the model's Delta set: the frequency-wise
    multiplicative uncertainty bound and samples of plausible models.

    Attributes
    ----------
    poles, zeros, integrators : int
        Model structure (poles include the fixed integrators).
    parameters : tuple of float
        Free denominator coefficients then numerator (see ``ModelStructure``).
    covariance : tuple of tuple of float
        Covariance of ``parameters`` (and of the delay, last, when it was estimated).
    delay_estimated : bool
    fit_estimation, fit_validation : float
        Fit in % (MATLAB definition) on estimation and held-out flights.
    source : str
        The flights it was identified from.
    """

    poles: int
    zeros: int
    integrators: int
    parameters: tuple[float, ...]
    covariance: tuple[tuple[float, ...], ...]
    delay_estimated: bool = False
    fit_estimation: float = float("nan")
    fit_validation: float = float("nan")
    source: str = ""

    def __post_init__(self) -> None:
        for key in ("poles", "zeros", "integrators"):
            value = getattr(self, key)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 0:
                raise SpecError(f"`identification.{key}`: got {value!r}, expected an integer >= 0")
        params = _vector(self.parameters, "identification.parameters")
        n = len(params) + (1 if self.delay_estimated else 0)
        if len(params) != self.poles - self.integrators + self.zeros + 1:
            raise SpecError(f"`identification.parameters`: {len(params)} values do not match poles={self.poles}, "
                            f"zeros={self.zeros}, integrators={self.integrators}")
        cov = check_covariance(self.covariance, n, "identification.covariance")
        object.__setattr__(self, "parameters", params)
        object.__setattr__(self, "covariance", tuple(tuple(float(v) for v in row) for row in cov))

    def bound(self, w: np.ndarray, delay: float) -> np.ndarray:
        """The fit's multiplicative uncertainty ``|Delta(jw)|`` at 3 standard deviations
        (:func:`ilcdob.uncertainty.multiplicative_bound`).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.
        delay : float
            The model's input delay, s.

        Returns
        -------
        numpy.ndarray
            One bound per frequency.
        """
        return multiplicative_bound(ModelStructure(self.poles, self.zeros, self.integrators),
                                    np.asarray(self.parameters), np.asarray(self.covariance), delay,
                                    self.delay_estimated, w)


@dataclass(frozen=True)
class LimitSpec:
    """What the vehicle can fly: the bound on its learning signal (m/s^2).

    A multirotor makes horizontal acceleration by tilting its thrust: at most
    ``g tan(tilt)`` with a tilt limit, ``g sqrt(k^2 - 1)`` with a thrust-to-weight ratio ``k``
    while holding its altitude. Give any of the three; the smallest bound counts
    (:attr:`max_acceleration`). The learning signal is checked against it
    (:mod:`ilcdob.design.law.limit`).

    Attributes
    ----------
    tilt : float or None
        Tilt limit of the attitude controller, degrees, in (0, 90).
    thrust_to_weight : float or None
        Maximum total thrust over weight, > 1.
    acceleration : float or None
        A direct bound on the commanded horizontal acceleration, m/s^2, > 0.
    """

    tilt: float | None = None
    thrust_to_weight: float | None = None
    acceleration: float | None = None

    def __post_init__(self) -> None:
        given = [k for k in ("tilt", "thrust_to_weight", "acceleration") if getattr(self, k) is not None]
        if not given:
            raise SpecError("`limits`: give at least one of `tilt` (degrees), `thrust_to_weight` (> 1) or "
                            "`acceleration` (m/s^2)")
        for key in given:
            object.__setattr__(self, key, _real(f"limits.{key}", getattr(self, key)))
        if self.tilt is not None and not 0.0 < self.tilt < 90.0:
            raise SpecError(f"`limits.tilt`: got {self.tilt!r}, expected a tilt limit in (0, 90) degrees")
        if self.thrust_to_weight is not None and not (math.isfinite(self.thrust_to_weight)
                                                      and self.thrust_to_weight > 1.0):
            raise SpecError(f"`limits.thrust_to_weight`: got {self.thrust_to_weight!r}, expected a ratio > 1 "
                            "(a vehicle must lift more than its weight to accelerate sideways)")
        if self.acceleration is not None:
            _positive("limits.acceleration", self.acceleration)

    @property
    def max_acceleration(self) -> float:
        """The smallest of the stated bounds, m/s^2."""
        bounds = []
        if self.tilt is not None:
            bounds.append(GRAVITY * math.tan(math.radians(self.tilt)))
        if self.thrust_to_weight is not None:
            bounds.append(GRAVITY * math.sqrt(self.thrust_to_weight ** 2 - 1.0))
        if self.acceleration is not None:
            bounds.append(self.acceleration)
        return min(bounds)

    def describe(self) -> str:
        """The bound and where it comes from, e.g. ``"6.87 m/s^2 (tilt 35 deg)"``."""
        parts = [f"tilt {self.tilt:g} deg" if self.tilt is not None else "",
                 f"thrust/weight {self.thrust_to_weight:g}" if self.thrust_to_weight is not None else "",
                 f"stated {self.acceleration:g} m/s^2" if self.acceleration is not None else ""]
        return f"{self.max_acceleration:.3g} m/s^2 ({', '.join(p for p in parts if p)})"


def check_noise_std(value: object, name: str) -> float:
    """A position-noise standard deviation in [0, 0.1) m, as a float; SpecError naming ``name`` otherwise.

    Parameters
    ----------
    value : object
        The value given.
    name : str
        The input's name, for the message.
    """
    v = float("nan") if isinstance(value, (bool, np.bool_)) else value
    if not isinstance(v, (int, float, np.floating)) or not (0.0 <= v < 0.1):
        raise SpecError(f"`{name}`: got {value!r}, expected a standard deviation in [0, 0.1) m")
    return float(v)


@dataclass(frozen=True)
class SensorSpec:
    """The position sensor of the vehicle.

    Attributes
    ----------
    noise_std : float
        Standard deviation of its white noise, m (>= 0, < 0.1). Sets the learning band when
        no trial is given to measure it from (:mod:`ilcdob.design.filters.band`).
    """

    noise_std: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "noise_std", check_noise_std(_real("sensor.noise_std", self.noise_std),
                                                              "sensor.noise_std"))


@dataclass(frozen=True)
class SystemSpec:
    """One vehicle: its true plant, the model its DOB and learning filters use, PID, DOB.

    Attributes
    ----------
    name : str
        Unique name in the fleet, following the rule of :func:`ilcdob.names.check_name`
        (1 to 64 ASCII letters, digits, spaces and ``_ - . +``, starting with a letter or digit).
    plant : PlantSpec
        The true plant (what the simulation flies). A python-control ``TransferFunction`` or
        ``StateSpace`` is accepted and converted with :meth:`PlantSpec.from_lti` (no delay;
        pass a ``PlantSpec.from_lti(sys, delay=...)`` for one).
    controller : PIDSpec
    dob : DOBSpec
    model : PlantSpec or None
        The nominal model ``P_hat`` used by ``M = Q/P_hat`` and by the learning filters;
        ``None`` means the model is exact (``P_hat = P``), as in the paper's simulations.
        Python-control systems are accepted as for ``plant``.
    noise : NoiseSpec
        The system's own process noise.
    identification : IdentificationSpec or None
        How the plant model was identified (None: derived or given).
    uncertainty : UncertaintySpec or None
        A stated multiplicative bound on the model error (defines the Delta set).
    limits : LimitSpec or None
        What the vehicle can fly: bounds its learning signal.
    sensor : SensorSpec or None
        Its position sensor's noise.
    """

    name: str
    plant: PlantSpec
    controller: PIDSpec
    dob: DOBSpec
    model: PlantSpec | None = None
    noise: NoiseSpec = field(default_factory=NoiseSpec)
    identification: IdentificationSpec | None = None
    uncertainty: UncertaintySpec | None = None
    limits: LimitSpec | None = None
    sensor: SensorSpec | None = None

    def __post_init__(self) -> None:
        check_name(self.name)
        for key in ("plant", "model"):
            value = getattr(self, key)
            if value is None and key == "model":
                continue
            if _is_lti(value):
                try:
                    object.__setattr__(self, key, PlantSpec.from_lti(value))
                except SpecError as exc:
                    raise SpecError(f"system {self.name!r}, `{key}`: {exc}") from exc
            elif not isinstance(value, PlantSpec):
                raise SpecError(f"system {self.name!r}, `{key}`: got {type(value).__name__} {value!r}; expected a "
                                "PlantSpec or a python-control TransferFunction or StateSpace")
        rel = self.nominal_plant.relative_degree
        if self.dob.q_order < rel:
            raise SpecError(
                f"system {self.name!r}: `dob.q_order` = {self.dob.q_order} makes M = Q/P_hat improper "
                f"(the plant model has relative degree {rel}); use q_order >= {rel}"
            )

    @property
    def nominal_plant(self) -> PlantSpec:
        """The plant model ``P_hat`` (the true plant when no model is given)."""
        return self.model if self.model is not None else self.plant

    def exact(self) -> "SystemSpec":
        """The same system with the nominal model as its true plant (Case I of the Theorem)."""
        return replace(self, plant=self.nominal_plant, model=None)
