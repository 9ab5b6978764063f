"""The learning band: where learning acts, and how its corner is chosen (docs/theory.md section 6).

Every learning filter of the Theorem contains the inverse of the previous vehicle's
disturbance map, ``L1_j = -(1 - Q_j) Gd_{j-1}^{-1}`` (paper Sec. III), whose gain grows like
``1/P_hat ~ s^2 (tau s + 1)``. On recorded trials two things break the exact inverse:

* **sensor noise**: white position noise of 0.5 mm through ``1/P_hat`` becomes tens to
  thousands of m/s^2 of learning signal at the Nyquist frequency, far beyond what a vehicle
  can fly;
* **model error**: where ``|Delta_{j-1}|`` reaches the Theorem's bound ``|1 + P C|/2`` the
  learning makes the error worse, not better.

The learning law therefore passes a zero-phase low-pass *F* (Butterworth of order ``n``,
run forwards and backwards) before and after the learning filter, over a horizon extended
at both ends::

    d_f,j = fold( F{ W{ learn( F{H{gamma e_{j-1}}}, F{H{d_f,{j-1}}} ) } } )

``learn`` is the method's learning filter (the Theorem's ``L1{.} + L2{.}`` for the closed
form), ``W`` the optional airframe correction (:mod:`ilcdob.design.maps.flown`), ``H`` the
extension of the trial by ``pad`` samples at each end (zeros before ``t = 0``, where the
vehicle is at rest; after the end the line fitted to the last :data:`END_FIT_S` seconds) and
``fold`` keeps the trial's samples and adds to its first ``pad`` samples, time-reversed, the
learning signal the law computed before ``t = 0`` (:func:`fold_start`). With
``F = W = gamma = 1`` it is the Theorem's law. Per frequency the filtered law leaves
``e_j = (1 - |F|) e'_j + |F| e_j,Theorem``: where ``F = 1`` it learns as the Theorem, where
``F = 0`` it leaves the error the DOB alone leaves.

Trial ends. ``F`` is zero-phase, so it spreads the learning signal up to about ``pad`` samples
before ``t = 0``, where no vehicle can fly it. Cropping that part leaves the learned error
without the pre-trial half of a symmetric response; folding it onto the trial's first samples
(:func:`fold_start`) keeps its integral, what the loops, slow next to ``F``, respond to. Fading the
learning signal in instead did worse on slow sinusoids, and fading it out at the end changed
nothing (the line continuation serves the end). The whole-trial figure of the band's law
(:mod:`..maps.finite_horizon`) can still exceed 1: a zero-phase filter cannot keep a per-frequency
bound for every disturbance of a finite trial (docs/theory.md section 6, "Trial ends"; measured:
docs/performance.md, "Measured figures behind the design's choices").

The corner ``w_c`` (:func:`choose_band`) is the smallest of three edges, each from what is
known:

``signal``
    From a trial: the highest frequency at which the error's spectrum (Welch) stands
    :data:`SNR_MIN` times above its noise floor (the median of the upper half of the band,
    where a vehicle's error is sensor noise). Above it the trial carries no information
    about the disturbance, only noise.
``noise budget``
    From the noise level (measured on the trial, or ``sensor.noise_std`` of the fleet) and
    the vehicle's acceleration limit: the largest corner whose noise-driven learning signal
    has an RMS of at most :data:`NOISE_SHARE` of the limit.
``model``
    From the previous vehicle's Delta set (identification covariance or stated bound): the
    largest corner at which both the filtered law's first-order worst case
    ``1 - |F| + |F| |Delta| / (|1 + P C|/2)`` (the paper's condition) and its exact worst case over
    the set's disc (the figure ``ilcdob check`` reports, :mod:`..checks.theorem`) exceed 1 by at most
    :data:`AMPLIFICATION_TOL` at any frequency; ``design`` and ``check`` then agree. Where no corner
    bounds the exact worst case (the disc reaches the source loop's stability boundary, ``W |T0| >= 1``,
    or the figure exceeds the tolerance below the lowest corner) the paper's condition alone sets the
    edge and the band says the improvement is not guaranteed, and why (docs/theory.md section 6).

No edge (noise-free data, no noise level, models trusted everywhere), or an edge above
:data:`OFF_FRACTION` of the Nyquist frequency, leaves the Theorem's filters unfiltered.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Callable

import numpy as np
from scipy import signal as sps
from scipy.integrate import trapezoid

from ilcdob.errors import SpecError
from ilcdob.signals import as_signal

__all__ = ["LearningBand", "NoiseEstimate", "estimate_noise", "choose_band", "check_bandwidth", "learning_horizon",
           "fold_start", "fade_out", "END_FIT_S", "FILTER_ORDER", "SNR_MIN", "NOISE_RESOLUTION", "NOISE_SHARE",
           "AMPLIFICATION_TOL", "OFF_FRACTION", "PAD_PERIODS", "MAX_PAD_SAMPLES", "NOISE_SAMPLES"]

#: Length of the trial end fitted by the line that extends it (:func:`learning_horizon`), s.
END_FIT_S = 0.25
#: Order of F's Butterworth prototype (each pass; F runs forwards and backwards, twice).
FILTER_ORDER = 4
#: The error's spectrum must stand this many times above the noise floor to be learned (6 dB).
#: With about 15 Welch averages (segments of ~N/8 samples, half overlap) a bin of pure
#: noise scatters around the floor with a standard deviation of ~0.26 of it: 4 is ~12
#: standard deviations above, so noise alone does not cross it.
SNR_MIN = 4.0
#: A noise below this standard deviation, m, is rounding, not a sensor (no position sensor
#: resolves a nanometre): the data count as noise-free.
NOISE_RESOLUTION = 1e-9
#: Share of the acceleration limit that the RMS of the noise-driven learning signal may use
#: (its peaks, about 4 RMS over a trial, then stay below half the limit).
NOISE_SHARE = 0.1
#: The filtered law may make the error at most this much worse at any frequency (first order).
AMPLIFICATION_TOL = 0.01
#: A corner above this share of the Nyquist frequency leaves the law unfiltered.
OFF_FRACTION = 0.5
#: Samples added at each end of the trial: this many periods of the corner frequency, where
#: F's impulse response has decayed.
PAD_PERIODS = 6
#: Most samples added at each end of a trial: the lowest corner is the one whose padding this is.
MAX_PAD_SAMPLES = 1_000_000

#: Fewest samples of a trial whose noise floor :func:`estimate_noise` estimates (one Welch window).
NOISE_SAMPLES = 64

_LOWEST = 1e-3   # lowest corner, as a share of the Nyquist frequency


def _line_tail(x: np.ndarray, n_fit: int, n_pad: int) -> np.ndarray:
    """``n_pad`` samples continuing ``x`` along the least-squares line through its last ``n_fit`` samples."""
    m = min(n_fit, x.size)
    k = np.arange(m, dtype=float)
    coef = np.polyfit(k, x[-m:], 1) if m > 1 else np.array([0.0, x[-1]])
    return np.polyval(coef, np.arange(m, m + n_pad, dtype=float))


def end_fit_samples(ts: float) -> int:
    """Samples of the trial end the extension's line is fitted to: :data:`END_FIT_S` s, at least 2.

    Parameters
    ----------
    ts : float
        Sample time, s.
    """
    return max(2, int(round(END_FIT_S / ts)))


def learning_horizon(x: object, ts: float, pad: int, n_fit: int | None = None) -> np.ndarray:
    """Extend one trial by ``pad`` samples at each end, as it is flown.

    Before ``t = 0`` the vehicle hovers at rest (zeros); after the end the signal continues
    along the least-squares line through its last :data:`END_FIT_S` seconds (long enough to
    average sensor noise, short enough to follow the trend at the end). A mirror image
    would bend the signal flat at the end and a point reflection about the last (noisy)
    sample adds a step; fed through the plant inverse, either grew from one learning
    iteration to the next on the nonlinear vehicles.

    Parameters
    ----------
    x : array
        One trial's signal, ``N`` samples.
    ts : float
        Sample time, s.
    pad : int
        Samples added at each end (>= 0; 0 returns ``x``).
    n_fit : int, optional
        Samples the line is fitted to (default :func:`end_fit_samples` of ``ts``).

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
    n_fit = end_fit_samples(ts) if n_fit is None else n_fit
    return np.concatenate([np.zeros(pad), x, _line_tail(x, n_fit, pad)])


def fold_start(z: np.ndarray, pad: int, n: int) -> np.ndarray:
    """The trial's ``n`` samples of ``z`` (computed on the horizon extended by ``pad`` at each end),
    with the part before ``t = 0`` folded onto the first samples (module docstring, trial ends).

    ``out[k] = z[pad + k] + z[pad - 1 - k]`` for ``k < min(pad, n)``, ``z[pad + k]`` after.

    Parameters
    ----------
    z : numpy.ndarray
        ``n + 2 pad`` samples (the learning signal on the extended horizon).
    pad : int
        Samples before ``t = 0``.
    n : int
        Samples of the trial.

    Returns
    -------
    numpy.ndarray
        ``n`` samples.
    """
    out = np.array(z[pad:pad + n], dtype=float)
    m = min(pad, n)
    if m:
        out[:m] += z[pad - m:pad][::-1]
    return out


def fade_out(m: int) -> np.ndarray:
    """Raised-cosine fade from 1 to 0 over ``m`` samples, ``0.5 (1 + cos(pi (k + 1)/(m + 1)))``, ``k = 0..m-1``.

    Both ends excluded: multiplied onto a signal's last ``m`` samples it takes it smoothly to zero
    at the first sample past them.

    Parameters
    ----------
    m : int
        Length, samples (>= 0).
    """
    k = np.arange(int(m), dtype=float)
    return 0.5 * (1.0 + np.cos(np.pi * (k + 1.0) / (m + 1.0)))


def check_bandwidth(value: object, ts: float | None, what: str = "--bandwidth") -> float | str | None:
    """A bandwidth request: ``"auto"``, ``None``/``"off"`` or a corner in [lowest, Nyquist) rad/s.

    The lowest corner pads each end of a trial by :data:`MAX_PAD_SAMPLES` (the filter is padded
    by :data:`PAD_PERIODS` periods of its corner): a corner of 1e-6 rad/s at 50 Hz would pad by
    10^9 samples, more memory than there is.

    Parameters
    ----------
    value : object
        The request; strings ``"auto"``, ``"off"`` or a number in text are accepted.
    ts : float or None
        Sample time, s (None: the corner is only checked to be positive and finite).
    what : str
        Name of the input in the message.

    Returns
    -------
    float or "auto" or None
        The corner (rad/s), ``"auto"`` or ``None`` (no filter).
    """
    if value is None or (isinstance(value, str) and value.strip().lower() == "off"):
        return None
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    nyq = math.pi / ts if ts is not None else math.inf
    try:
        wc = float(value) if not isinstance(value, bool) else float("nan")  # type: ignore[arg-type]
    except (TypeError, ValueError):
        wc = float("nan")
    lowest = PAD_PERIODS * 2 * math.pi / (MAX_PAD_SAMPLES * ts) if ts is not None else 0.0
    if not (math.isfinite(wc) and 0.0 < wc < nyq and wc >= lowest):
        where = (f"(0, {nyq:.4g}) rad/s (the Nyquist frequency at Ts = {ts:g} s), at least {lowest:.4g} rad/s (a "
                 f"lower corner pads each trial end by more than {MAX_PAD_SAMPLES:,} samples)" if ts is not None
                 else "rad/s > 0")
        raise SpecError(f"`{what}`: got {value!r}, expected 'auto', 'off' or a corner frequency in {where}")
    return wc


@dataclass(frozen=True)
class LearningBand:
    """The robustness filter F of the learning law (module docstring) and why its corner is where it is.

    Attributes
    ----------
    ts : float
        Sample time, s.
    cutoff : float or None
        Corner ``w_c`` of F's Butterworth prototype, rad/s; ``None``: no filter (the
        Theorem's filters as they are, on the trial as recorded).
    order : int
        Butterworth order ``n`` of each pass (1..8).
    source : str
        ``"stated"`` (given), ``"data"`` (chosen from a trial), ``"fleet"`` (chosen from the
        fleet's Delta set, sensor noise and limit) or ``"off"``.
    edges : dict of str to float or None
        The candidate corners (rad/s) that were computed: ``signal``, ``noise budget``,
        ``model``; None where the edge does not limit.
    noise_std : float or None
        Position-noise standard deviation used, m (measured on the trial or stated).
    reason : str
        One sentence on the choice.
    """

    ts: float
    cutoff: float | None
    order: int = FILTER_ORDER
    source: str = "stated"
    edges: dict[str, float | None] = field(default_factory=dict)
    noise_std: float | None = None
    reason: str = ""

    def __post_init__(self) -> None:
        if not (isinstance(self.ts, (int, float)) and math.isfinite(self.ts) and self.ts > 0):
            raise SpecError(f"`ts`: got {self.ts!r}, expected a sample time > 0 s")
        if self.cutoff is not None:
            object.__setattr__(self, "cutoff", check_bandwidth(self.cutoff, self.ts, "cutoff"))
        n = self.order
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 8:
            raise SpecError(f"`order`: got {n!r}, expected an integer in 1..8")

    @cached_property
    def sos(self) -> np.ndarray | None:
        """Second-order sections of one pass of F (``scipy.signal.butter``, designed once), None
        without a filter."""
        if self.cutoff is None:
            return None
        return sps.butter(self.order, self.cutoff / (math.pi / self.ts), output="sos")

    @property
    def pad(self) -> int:
        """Samples added at each end of the trial (:data:`PAD_PERIODS` periods of the corner)."""
        if self.cutoff is None:
            return 0
        return int(PAD_PERIODS * math.ceil(2 * math.pi / self.cutoff / self.ts))

    def response(self, w: object) -> np.ndarray:
        """The gain of F on the learning signal, ``|H(e^{j w Ts})|^4`` (two forward-backward passes).

        ``scipy.signal.butter`` designs ``H`` by the bilinear transform with the corner
        prewarped, so ``|H|^2 = 1 / (1 + (tan(w Ts/2) / tan(w_c Ts/2))^(2n))`` exactly: the gain
        is evaluated from that, without designing the filter (the corner searches of
        :func:`choose_band` evaluate it for dozens of corners per trial).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Real gains in [0, 1] (ones without a filter).
        """
        w = np.asarray(w, dtype=float)
        if self.cutoff is None:
            return np.ones_like(w)
        ratio = np.tan(0.5 * w * self.ts) / math.tan(0.5 * self.cutoff * self.ts)
        return 1.0 / (1.0 + ratio ** (2 * self.order)) ** 2

    def smooth(self, x: np.ndarray) -> np.ndarray:
        """One forward-backward pass of F over an extended trial (``sosfiltfilt``, no padding).

        Parameters
        ----------
        x : numpy.ndarray
            The extended trial (:func:`learning_horizon`).

        Returns
        -------
        numpy.ndarray
            The filtered signal (``x`` itself without a filter).
        """
        if self.cutoff is None:
            return x
        return sps.sosfiltfilt(self.sos, x, padtype=None)

    def describe(self) -> str:
        """One line: the corner (or no filter) and why."""
        if self.cutoff is None:
            return f"off: {self.reason}" if self.reason else "off"
        return f"{self.cutoff:.4g} rad/s ({self.source}; {self.reason})" if self.reason else f"{self.cutoff:.4g} rad/s"

    def to_dict(self) -> dict[str, Any]:
        """What ``filters.json`` records (key ``band``): the corner, why, and F's coefficients.

        Returns
        -------
        dict
            ``cutoff_rad_s`` (None: no filter), ``order``, ``source``, ``reason``, ``edges_rad_s``,
            ``noise_std_m``, and with a filter ``sos`` (one pass), ``zi`` (the steady-state
            state per unit input, ``scipy.signal.sosfilt_zi``, that the backward passes start
            from), ``pad`` and ``end_fit`` (samples), ``start`` (``"fold"``: the part of the
            learning signal before ``t = 0`` is added, time-reversed, to the trial's first ``pad``
            samples, :func:`fold_start`), ``output_start`` (``"rest"``: the pass of F on the learning
            signal starts its forward filter from rest, docs/theory.md section 6) and ``rule``.
        """
        out: dict[str, Any] = {"cutoff_rad_s": self.cutoff, "order": int(self.order), "source": self.source,
                               "reason": self.reason, "edges_rad_s": dict(self.edges), "noise_std_m": self.noise_std}
        if self.cutoff is not None:
            sos = self.sos
            out.update({"sos": sos.tolist(), "zi": sps.sosfilt_zi(sos).tolist(), "pad": self.pad,
                        "end_fit": end_fit_samples(self.ts), "start": "fold", "output_start": "rest",
                        "rule": "d_f = fold(F{W{L1{F{H{e}}} + L2{F{H{d_f_prev}}}}}): H extends the trial by `pad` "
                                "samples (zeros before, the line through the last `end_fit` samples after); F is "
                                "`sos` run forwards then backwards (scipy.signal.sosfiltfilt, padtype=None; the outer F's "
                                "forward run from rest, output_start); with z "
                                "the result on the extended horizon (n + 2 pad samples), fold gives d_f[k] = "
                                "z[pad + k] + z[pad - 1 - k] for k < min(pad, n) and z[pad + k] after"})
        return out


@dataclass(frozen=True)
class NoiseEstimate:
    """The noise floor of a trial's error and the band where the error stands above it.

    Attributes
    ----------
    std : float
        Standard deviation of the white part of the error, m (``sqrt(floor fs / 2)``).
    floor : float
        One-sided noise power density, m^2/Hz: the median Welch density over the upper half
        of the band.
    edge : float or None
        Highest frequency where the density is at least :data:`SNR_MIN` x ``floor``, rad/s;
        None when it stays above up to the Nyquist frequency or the floor is not resolved.
    f : numpy.ndarray
        Welch frequencies, Hz.
    psd : numpy.ndarray
        Welch density, m^2/Hz.
    """

    std: float
    floor: float
    edge: float | None
    f: np.ndarray
    psd: np.ndarray


def estimate_noise(e: object, ts: float) -> NoiseEstimate:
    """Noise floor and signal edge of one trial's tracking error (module docstring, ``signal`` edge).

    Welch's method (Hann windows of a power of two near ``N/8`` samples, 64 to 4096, half
    overlap, each segment's line removed). The floor is the median density above half the
    Nyquist frequency: there a vehicle's measured error is its sensor noise. A floor below
    ``1e-14`` of the peak density, or a noise below :data:`NOISE_RESOLUTION`, is not resolved
    (noise-free data, rounding): ``std = 0``, no edge.

    Parameters
    ----------
    e : array, m
        The trial's measured tracking error (at least :data:`NOISE_SAMPLES` samples).
    ts : float
        Sample time, s.

    Returns
    -------
    NoiseEstimate
    """
    e = as_signal(e, "e_prev")
    if e.size < NOISE_SAMPLES:
        raise SpecError(f"`e_prev`: got {e.size} samples, expected at least {NOISE_SAMPLES} to estimate the noise "
                        "floor")
    nper = int(min(4096, max(64, 2 ** round(math.log2(e.size / 8)))))
    f, p = sps.welch(e, fs=1.0 / ts, nperseg=nper, detrend="linear")
    nyq = 0.5 / ts
    floor = float(np.median(p[f >= 0.5 * nyq]))
    peak = float(np.max(p))
    std = math.sqrt(max(floor, 0.0) / (2.0 * ts))
    if peak <= 0.0 or floor <= 1e-14 * peak or std < NOISE_RESOLUTION:
        return NoiseEstimate(0.0, floor, None, f, p)
    above = np.flatnonzero(p >= SNR_MIN * floor)
    edge = None
    if above.size and f[above[-1]] < 0.5 * nyq:
        edge = float(2 * math.pi * max(f[above[-1]], f[1]))
    elif not above.size:
        edge = float(2 * math.pi * f[1])
    return NoiseEstimate(std, floor, edge, f, p)


def _largest_corner(ts: float, ok: Callable[[float], bool]) -> float | None:
    """The largest corner in [1e-3 Nyquist, Nyquist) with ``ok(corner)`` (monotone: true below some
    corner), by bisection in log frequency; None when the Nyquist end is already ok."""
    nyq = math.pi / ts
    hi, lo = 0.999 * nyq, _LOWEST * nyq
    if ok(hi):
        return None
    if not ok(lo):
        return lo
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
        if hi / lo < 1.001:
            break
    return lo


def _noise_budget_edge(ts: float, order: int, noise_std: float, a_max: float,
                       l1_gain: Callable[[np.ndarray], np.ndarray]) -> float | None:
    """Largest corner with ``noise_std sqrt(Ts/pi int |L1 W|^2 |F|^2 dw) <= NOISE_SHARE a_max``."""
    w = np.linspace(0.0, math.pi / ts, 4097)[1:]
    g2 = np.abs(l1_gain(w)) ** 2
    budget = NOISE_SHARE * a_max

    def ok(wc: float) -> bool:
        f2 = LearningBand(ts, wc, order, "stated").response(w) ** 2
        rms = noise_std * math.sqrt(ts / math.pi * trapezoid(g2 * f2, w))
        return rms <= budget

    return _largest_corner(ts, ok)


def _model_edge(ts: float, order: int, w: np.ndarray, ratio: np.ndarray) -> float | None:
    """Largest corner with ``max F(w) (ratio(w) - 1)_+ <= AMPLIFICATION_TOL`` (``ratio = |Delta|/rhs``)."""
    excess = np.maximum(np.asarray(ratio, float) - 1.0, 0.0)
    if not np.any(excess > 0):
        return None

    def ok(wc: float) -> bool:
        return float(np.max(LearningBand(ts, wc, order, "stated").response(w) * excess)) <= AMPLIFICATION_TOL

    return _largest_corner(ts, ok)


def _exact_edge(ts: float, order: int, w: np.ndarray, worst: Callable[[np.ndarray], np.ndarray]) -> tuple[
        float | None, str]:
    """Largest corner with ``max worst(F) <= 1 + AMPLIFICATION_TOL``, and why none does ("" where one does): the
    worst case is unbounded for every ``F != 0`` where the Delta set reaches the source's stability boundary, or
    it exceeds the tolerance below the lowest corner a band has. ``worst(F)`` is convex in a real ``F`` in
    [0, 1] with ``worst(0) = 1``, so a lower corner never does worse and the bisection is sound."""
    def ok(wc: float | None) -> bool:
        f = LearningBand(ts, wc, order, "stated").response(w)
        with np.errstate(invalid="ignore"):
            return bool(np.max(worst(f)) <= 1.0 + AMPLIFICATION_TOL)

    if ok(None):
        return None, ""
    lowest = _LOWEST * math.pi / ts
    if not ok(lowest):
        with np.errstate(invalid="ignore"):
            bad = w[~np.isfinite(worst(np.ones(w.size)))]
        why = (f"the Delta set reaches the source loop's stability boundary ({bad.min():.4g}-{bad.max():.4g} rad/s)"
               if bad.size else f"the exact worst case exceeds it below the lowest corner, {lowest:.4g} rad/s")
        return None, why
    edge = _largest_corner(ts, ok)
    return (0.999 * math.pi / ts if edge is None else edge), ""


def choose_band(ts: float, request: object = "auto", *, error: object | None = None, noise_std: float | None = None,
                a_max: float | None = None, l1_gain: Callable[[np.ndarray], np.ndarray] | None = None,
                trust: tuple[np.ndarray, np.ndarray] | None = None,
                exact: tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]] | None = None,
                order: int = FILTER_ORDER) -> LearningBand:
    """The learning band for one pair: stated, or chosen from a trial and the fleet (module docstring).

    Parameters
    ----------
    ts : float
        Sample time, s.
    request : "auto", None/"off" or float
        ``"auto"`` chooses; ``None`` or ``"off"``: no filter; a number: that corner, rad/s.
    error : array, m, optional
        The previous vehicle's measured tracking error on the trial learned from (``signal``
        edge and noise level).
    noise_std : float, optional
        Stated position-noise standard deviation, m (used when no ``error`` is given).
    a_max : float, optional
        The learning vehicle's acceleration limit, m/s^2 (``noise budget`` edge).
    l1_gain : callable, optional
        ``w -> |L1 W|(e^{j w Ts})`` of the pair (``noise budget`` edge).
    trust : (w, ratio), optional
        Frequencies (rad/s) and ``|Delta_{j-1}| / (|1 + P C|/2)`` of the previous vehicle's
        Delta set (``model`` edge).
    exact : (w, worst), optional
        Frequencies (rad/s) and ``worst(F)``: the exact worst case over the same set for a band gain ``F`` on
        them (:func:`~..checks.theorem.exact_worst_on_set`; ``model`` edge).
    order : int
        Butterworth order of F.

    Returns
    -------
    LearningBand
    """
    request = check_bandwidth(request, ts)
    if request is None:
        return LearningBand(ts, None, order, "off", reason="the method's filters unfiltered, as asked")
    edges: dict[str, float | None] = {}
    std = noise_std
    if error is not None:
        est = estimate_noise(error, ts)
        edges["signal"] = est.edge
        std = est.std
    if std and a_max is not None and l1_gain is not None:
        edges["noise budget"] = _noise_budget_edge(ts, order, std, a_max, l1_gain)
    unbounded, needed = "", False
    if trust is not None:
        edges["model"] = _model_edge(ts, order, *trust)
    if exact is not None:
        edge, why = _exact_edge(ts, order, *exact)
        if why:
            unbounded = (f"; not guaranteed: no corner keeps the exact worst case within 1 + {AMPLIFICATION_TOL:g} "
                         f"({why}; ilcdob check)")
        elif edge is not None:
            edges["model"], needed = min(edge, edges.get("model") or edge), True
    if request != "auto":
        return LearningBand(ts, float(request), order, "stated", edges, std, "stated with --bandwidth")
    source = "data" if error is not None else "fleet"
    finite = {k: v for k, v in edges.items() if v is not None}
    nyq = math.pi / ts
    if not finite:
        trusted = ("" if trust is None else " and the paper's condition holds at every frequency" if unbounded
                   else " and the models are trusted at every frequency")
        why = ("the trial's error has no resolved noise floor" if error is not None
               else "no trial, no stated sensor noise") + trusted
        return LearningBand(ts, None, order, "off", edges, std, why + unbounded)
    name = min(finite, key=finite.get)
    wc = finite[name]
    if wc >= OFF_FRACTION * nyq and not (needed and name == "model"):  # the exact worst case needs the band
        return LearningBand(ts, None, order, "off", edges, std,
                            f"every edge is above {OFF_FRACTION:g} x Nyquist (lowest: {name}, {wc:.4g} rad/s)"
                            + unbounded)
    return LearningBand(ts, wc, order, source, edges, std, f"set by the {name} edge" + unbounded)

