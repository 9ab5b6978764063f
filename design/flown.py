"""The learning law as flown on a real vehicle with wrong models.

The Theorem (paper Sec. III, docs/theory.md section 2) gives the closed-form learning law
``d_f,j = L1_j{e_{j-1}} + L2_j{d_f,{j-1}}`` for plants that are exactly the paper's loop
``y = P{u2 + d}`` (Sec. II, docs/theory.md section 1). On a vehicle the models are
identified and therefore wrong, the position is measured with noise, the trial has ends and
the wind pushes the airframe instead of adding to the command. Flown as is on the nonlinear
quadrotors of :mod:`ilcdob.vehicles.quadrotor` (the "real vehicles" of
:mod:`ilcdob.validation.nonlinear`), the Theorem's law diverges within three iterations. Four
causes, each fixed at its root (numbers from the development runs, 0.5 mm sensor noise):

* **Sensor noise through the plant inverse.** ``L1 = -(1 - Q_j) Gd_{j-1}^{-1}`` contains
  ``1/P_hat ~ s^2 (tau s + 1)``, gain ~1e5 at the Nyquist frequency: 0.5 mm of white
  position noise became tens of m/s^2 of learning signal and the tilt limit saturated. The
  learning passes a zero-phase low-pass *robustness filter* F before and after the plant
  inverse (:func:`robustness_filter`). Its default corner, 10 rad/s
  (:data:`LEARNING_CUTOFF`), is above every disturbance of the scenarios (0.94 and
  1.41 rad/s, half-wave harmonics up to ~8.5 rad/s) and below the band where ``1/P_hat``
  amplifies sensor noise and where the identified models' error reaches the Theorem's bound
  ``|1 + P C|/2``.
* **Trial boundaries.** Whatever the extension of the trial, the inverse turns a jump in a
  derivative into a spike, and iterating made spikes at the start and end of the trial
  grow (trial-domain instability that the frequency check cannot show). The filters run
  over a horizon extended as the flight is flown (:func:`learning_horizon`): at rest
  before ``t = 0``, a line fitted to the last 0.25 s after the end.
* **Where the wind acts.** The wind pushes the airframe, the command first passes the
  attitude loop ``A = s^2 P``: each vehicle's command-side equivalent of the same wind is
  ``A_j^{-1}{d}``. The Theorem with these wind maps gains the factor
  ``W = A_hat_{j-1}/A_hat_j`` (:func:`airframe_path_filter`); without it UAV3, learning
  from UAV1 (tau 0.139 vs 0.100 s), kept ~5 mm of error at the fixed point (noise-free,
  scenario 1), and the full run leaves 1-6 % of the DOB-only RMSE instead of 0.5-3 %.
* **One-pass convergence.** With exact models the law reaches its fixed point in one
  flight (as the paper reports, Sec. IV: learning converges in the first iteration) and
  from then on copies the previous vehicle's sensor noise and residual every flight, so
  iterations 1-3 stay on that floor, a few percent apart in either direction. A learning
  gain ``gamma < 1`` averages them over the chain: the error falls by the factor
  ``1 - gamma`` per flight to the same floor instead of jumping there; the path changes,
  the final accuracy does not. Measured on the full nonlinear reproduction (seed 0),
  learning 1 / 2 / 3 over the DOB-only RMSE: gain 1 (the Theorem's law, the default),
  0.44-3.33 % / 0.38-3.33 % / 0.36-3.35 %; gain 0.5, 12-50 % / 1.5-7.2 % / 0.46-2.97 %.

So the law flown is (:class:`VehicleLearning`, built by :func:`vehicle_learning`)::

    d_f,j = F{ W{ L1_j{ F{gamma e_{j-1} + Gf_{j-1}{d_f,{j-1}}} } } }

which with ``F = W = gamma = 1`` is the Theorem's ``L1_j{e_{j-1}} + L2_j{d_f,{j-1}}``.

The models are ``P_hat = A_hat / s^2``: an attitude chain behind the rigid body's two
integrators, e.g. the identified ``b0 / (s^2 (s + a0))``. :func:`model_attitude` gives the
model's ``A_hat`` in discrete time, with which a command-side estimate is expressed as the
airframe acceleration it stands for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal
from ilcdob.specs import PlantSpec

from .closed_form import LearningFilters, closed_form_filters, simulate_map

__all__ = ["VehicleLearning", "vehicle_learning", "model_attitude", "airframe_path_filter", "learning_horizon",
           "robustness_filter", "END_FIT_S", "LEARNING_CUTOFF", "LEARNING_FILTER_ORDER"]

#: Length of the trial end fitted by the line that extends it (:func:`learning_horizon`), s.
END_FIT_S = 0.25

#: Default corner of the robustness filter F, rad/s (module docstring).
LEARNING_CUTOFF = 10.0

#: Default order of F's Butterworth prototype (applied forwards and backwards).
LEARNING_FILTER_ORDER = 4


def _rigid_body_split(plant: PlantSpec, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of the attitude chain ``A_hat = s^2 P_hat`` of a model ``A_hat/s^2``."""
    num = np.trim_zeros(np.asarray(plant.num, float), "f")
    den = np.trim_zeros(np.asarray(plant.den, float), "f")
    k = 0
    while den.size > 1 and den[-1] == 0.0:
        den, k = den[:-1], k + 1
    if k != 2 or num[-1] == 0.0:
        raise SpecError(f"model of {name!r}: got P_hat = {list(plant.num)}/{list(plant.den)} with {k} "
                        "integrator(s); the nonlinear vehicles need models A(s)/s^2 (attitude chain times "
                        "the rigid body's two integrators), e.g. b0/(s^2 (s + a0))")
    return num, den


def model_attitude(loop: LoopSystem) -> tuple[np.ndarray, np.ndarray, int]:
    """The model's attitude chain ``A_hat = s^2 P_hat`` under zero-order hold.

    Parameters
    ----------
    loop : LoopSystem
        The loop whose model ``P_hat`` (``loop.spec.nominal_plant``) is ``A_hat/s^2``.

    Returns
    -------
    (b, a, delay) : (numpy.ndarray, numpy.ndarray, int)
        ``z^-1`` coefficients for :func:`scipy.signal.lfilter` and the model's input delay
        in whole samples (rounded).

    Raises
    ------
    SpecError
        The model does not have exactly two integrators (or has a zero at the origin).
    """
    num, den = _rigid_body_split(loop.spec.nominal_plant, loop.name)
    b, a, _ = sps.cont2discrete((num, den), loop.ts, method="zoh")
    return np.atleast_1d(np.squeeze(b)), np.atleast_1d(a), int(round(loop.spec.nominal_plant.delay / loop.ts))


def _linear_tail(x: np.ndarray, n_fit: int, n_pad: int) -> np.ndarray:
    """``n_pad`` samples continuing ``x`` along the least-squares line through its last
    ``n_fit`` samples (robust to noise, keeps the slope)."""
    m = min(n_fit, x.size)
    k = np.arange(m, dtype=float)
    coef = np.polyfit(k, x[-m:], 1) if m > 1 else np.array([0.0, x[-1]])
    return np.polyval(coef, np.arange(m, m + n_pad, dtype=float))


def learning_horizon(x: object, ts: float, pad: int) -> np.ndarray:
    """Extend one trial by ``pad`` samples at each end, as it is flown.

    Before ``t = 0`` the vehicle hovers at rest (zeros); after the end the signal continues
    along the least-squares line through its last :data:`END_FIT_S` seconds (0.25 s: long
    enough to average the sensor noise, short enough to follow the trend at the end; with
    1 s the end of scenario 4, where the half-wave wind has a kink at 59.99 s, was learned
    badly).

    A mirror image at the end would bend the signal flat there, a point reflection about the
    last (noisy) sample adds a step; an end-to-end zero-phase filter whose start is cut at
    ``t = 0`` hands the plant inverse a jump in the derivatives. Each of these, fed through
    ``1/P_hat``, grew from one learning iteration to the next on the nonlinear vehicles.

    Parameters
    ----------
    x : array
        One trial's signal, ``N`` samples.
    ts : float
        Sample time, s.
    pad : int
        Samples added at each end (>= 0; 0 returns ``x``).

    Returns
    -------
    numpy.ndarray
        ``N + 2 pad`` samples, ``x`` at ``[pad:pad + N]``.
    """
    x = as_signal(x, "x")
    if isinstance(pad, bool) or not isinstance(pad, (int, np.integer)) or pad < 0:
        raise SpecError(f"`pad`: got {pad!r}, expected an integer number of samples >= 0")
    if pad == 0:
        return x
    return np.concatenate([np.zeros(pad), x, _linear_tail(x, max(2, int(round(END_FIT_S / ts))), pad)])


def robustness_filter(x: object, ts: float, cutoff: float, order: int = LEARNING_FILTER_ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass ``F`` (forward-backward, ``|F| = 1/(1 + (w/w_c)^(2n))``).

    Parameters
    ----------
    x : array
        Signal, already extended (:func:`learning_horizon`); run without further padding.
    ts : float
        Sample time, s.
    cutoff : float
        Corner ``w_c`` of the prototype, rad/s, below the Nyquist frequency ``pi/ts``.
    order : int
        Prototype order ``n`` (1..8).

    Returns
    -------
    numpy.ndarray
        The filtered signal, same length as ``x``.
    """
    x = as_signal(x, "x")
    nyq = math.pi / ts
    if isinstance(cutoff, bool) or not isinstance(cutoff, (int, float)) or not 0.0 < cutoff < nyq:
        raise SpecError(f"`cutoff`: got {cutoff!r} rad/s, expected a frequency in (0, {nyq:.4g}) rad/s "
                        f"(the Nyquist frequency at Ts = {ts:g} s)")
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= 8:
        raise SpecError(f"`order`: got {order!r}, expected an integer in 1..8")
    sos = sps.butter(order, cutoff / nyq, output="sos")
    return sps.sosfiltfilt(sos, x, padtype=None)


def airframe_path_filter(source: LoopSystem, target: LoopSystem) -> tuple[np.ndarray, np.ndarray]:
    """Discrete ``W = A_hat_{j-1} / A_hat_j = P_hat_{j-1} / P_hat_j`` (Tustin): the
    airframe-wind correction of the learning filter.

    The wind acts on the rigid body (``x'' = A{u2} + d``), not at the command input that
    the paper's loop ``y = P{u2 + d}`` (Sec. II) assumes. Its command-side equivalent
    differs per vehicle, ``A_j^{-1}{d}``, so vehicle j-1's data reconstruct *its* equivalent
    and vehicle j needs its own. With the wind maps ``Gd_j = P_j (1 - Q_j)/D_j * A_j^{-1}``
    in the Theorem's ``L1_j = (Gf_j Gd_{j-1})^{-1} Gd_j`` (paper Sec. III, docs/theory.md
    section 2) the paper's L1 gains exactly the factor ``A_{j-1}/A_j``, built here from the
    models (``A_hat = s^2 P_hat``). Around a cycle of the fleet the factors multiply to 1.

    Parameters
    ----------
    source : LoopSystem
        Loop of vehicle j-1 (the trial learned from), built from its model.
    target : LoopSystem
        Loop of vehicle j (the one that flies the learning signal).

    Returns
    -------
    (b, a) : numpy.ndarray
        ``z^-1`` coefficients of W for :func:`scipy.signal.lfilter`.

    Raises
    ------
    SpecError
        A model is not ``A(s)/s^2``, the model delays differ, or ``A_hat_j`` has a zero in
        the closed right half plane (W would be unstable).
    """
    ns, ds = _rigid_body_split(source.spec.nominal_plant, source.name)
    nt, dt_ = _rigid_body_split(target.spec.nominal_plant, target.name)
    ps, pt = source.spec.nominal_plant, target.spec.nominal_plant
    if abs(ps.delay - pt.delay) > 1e-9:
        raise SpecError(f"models of {source.name!r} and {target.name!r}: delays {ps.delay:g} s and "
                        f"{pt.delay:g} s differ; the airframe correction needs equal model delays")
    zt = np.roots(nt) if nt.size > 1 else np.zeros(0)
    if np.any(zt.real >= 0):
        raise SpecError(f"model of {target.name!r}: zeros {zt} in the closed right half plane; "
                        "A_hat_j-1/A_hat_j would be unstable")
    b, a = sps.bilinear(np.polymul(ns, dt_), np.polymul(ds, nt), fs=1.0 / source.ts)
    return np.atleast_1d(b), np.atleast_1d(a)


@dataclass(frozen=True)
class VehicleLearning:
    """The learning law flown on the vehicles (module docstring)::

        d_f,j = F{ W{ L1_j{ F{gamma e_{j-1} + Gf_{j-1}{d_f,{j-1}}} } } }

    which with ``F = W = gamma = 1`` is the Theorem's ``L1_j{e_{j-1}} + L2_j{d_f,{j-1}}``
    (paper Sec. III, docs/theory.md section 2), evaluated as in
    :meth:`ilcdob.design.LearningFilters.apply` (``L2 = L1 Gf_{j-1}``).

    Parameters
    ----------
    filters : LearningFilters
        The closed-form filters of the Theorem from the identified models.
    path : tuple of numpy.ndarray or None
        ``(b, a)`` of the airframe correction W (:func:`airframe_path_filter`), or ``None``
        for the paper's law as is (wind assumed at the command input).
    cutoff : float or None
        Corner of the robustness filter F, rad/s (:func:`robustness_filter`); ``None``:
        ``F = 1`` and no horizon extension.
    order : int
        Butterworth order of F.
    gain : float
        Learning gain ``gamma`` in (0, 1] on the new error: ``gamma L1{e_{j-1}} +
        L2{d_f,{j-1}}`` (1: the Theorem's law).
    """

    filters: LearningFilters
    path: tuple[np.ndarray, np.ndarray] | None
    cutoff: float | None
    order: int = LEARNING_FILTER_ORDER
    gain: float = 1.0

    @property
    def pad(self) -> int:
        """Samples added at each end of the trial (:func:`learning_horizon`): six periods of
        the corner frequency, where F's impulse response has decayed."""
        if self.cutoff is None:
            return 0
        return int(6 * math.ceil(2 * math.pi / self.cutoff / self.filters.source.ts))

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of vehicle j from vehicle j-1's trial.

        Parameters
        ----------
        e_prev : array, m
            Vehicle j-1's *measured* tracking error.
        df_prev : array, m/s^2
            The learning signal vehicle j-1 flew with (zeros if none).

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2, same length.
        """
        lf = self.filters
        ts = lf.source.ts
        e = as_signal(e_prev, "e_prev")
        df_prev = as_signal(df_prev, "df_prev", e.size)
        e_virtual = self.gain * e
        if np.any(df_prev):
            e_virtual = e_virtual + simulate_map(lf.source.G_f, df_prev)
        pad = self.pad
        x = learning_horizon(e_virtual, ts, pad)
        if self.cutoff is not None:
            x = robustness_filter(x, ts, self.cutoff, self.order)
        df = lf.L1.apply(x, "e_prev")
        if self.path is not None:
            df = sps.lfilter(self.path[0], self.path[1], df)
        if self.cutoff is not None:
            df = robustness_filter(df, ts, self.cutoff, self.order)
        return df[pad:pad + e.size]


def vehicle_learning(source: LoopSystem, target: LoopSystem, *, cutoff: float | None = LEARNING_CUTOFF,
                     order: int = LEARNING_FILTER_ORDER, airframe_disturbance: bool = True, gain: float = 1.0,
                     filters: LearningFilters | None = None) -> VehicleLearning:
    """The learning law of one pair as flown on the vehicles (module docstring).

    Parameters
    ----------
    source : LoopSystem
        Loop of vehicle j-1 built from its model (the trial learned from).
    target : LoopSystem
        Loop of vehicle j built from its model (the one that flies the learning signal).
    cutoff : float or None
        Corner of the robustness filter F, rad/s; ``None`` disables F and the horizon
        extension.
    order : int
        Butterworth order of F (1..8).
    airframe_disturbance : bool
        Learn with the wind's true path (it acts on the airframe): include the correction W
        of :func:`airframe_path_filter`. ``False`` flies the paper's law as is, which assumes
        the wind at the command input.
    gain : float
        Learning gain ``gamma`` in (0, 1].
    filters : LearningFilters, optional
        The closed-form filters of the pair (paper Sec. III), when already designed;
        default: :func:`~ilcdob.design.closed_form_filters` of ``source`` and ``target``.

    Returns
    -------
    VehicleLearning
    """
    lf = filters if filters is not None else closed_form_filters(source, target)
    path = airframe_path_filter(source, target) if airframe_disturbance else None
    return VehicleLearning(lf, path, cutoff, order, gain)
