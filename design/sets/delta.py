"""The Delta set: plausible true plants around a system's model (docs/theory.md section 3).

Two sources:

* an identified model (``SystemSpec.identification``): parameters drawn from the fit's
  Gaussian ``N(theta, Cov)`` (optionally with the covariance scaled, ``scale`` > 1 to go
  beyond the identified uncertainty), and the frequency-wise 3-sigma bound ``|Delta(jw)|``;
* a bound given in the fleet file (``uncertainty = { bound = 0.2 }``): multiplicative
  errors ``P = (1 + Delta) P_hat`` with ``Delta`` a real gain in ``[-bound, bound]`` or a
  first-order high-pass ``bound * sign * s tau / (s tau + 1)`` (unmodelled fast dynamics),
  so ``|Delta(jw)| <= bound`` at every frequency.

Each sample becomes a :class:`~ilcdob.loop.LoopSystem` whose true plant is the sample and
whose DOB and learning filters keep using the nominal model, exactly as a vehicle flies.
Samples whose loop is unstable are redrawn (and counted); so, given a margin ``m`` > 0, are those
whose disturbance map leaves the model's by more than ``1/m`` at some frequency,
``max_w |Gd(w)/Gd_hat(w)| > 1/m`` (:func:`disturbance_peak`). Without a margin a large bound
admits plants arbitrarily close to the stability boundary of their loop, whose disturbance
response is arbitrarily resonant; no learning filter that passes any band can be guaranteed for
all of them (docs/theory.md section 3, "Robust-set over a structured Delta set").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ilcdob.channel_loop import ChannelLoop, channel_loop
from ilcdob.errors import SpecError, UnstableLoopError
from ilcdob.loop import LoopSystem, build_loop, freqresp
from ilcdob.specs import IdentificationSpec, PlantSpec, SystemSpec
from ilcdob.uncertainty import ModelStructure

__all__ = ["sampled_bound", "ALIASES", "TAU_RANGE", "DeltaSet", "delta_set", "channel_delta_set", "delta_bound",
           "check_scale", "disturbance_peak", "dense_grid", "MAX_DELTA_SAMPLES"]

#: Time constants of the high-pass errors of a fleet bound (s): log-uniform in this range.
TAU_RANGE = (0.01, 1.0)

#: Most sampled plants per system in a Delta set (the fir/robust designs grow with their number).
MAX_DELTA_SAMPLES = 200


@dataclass(frozen=True)
class DeltaSet:
    """Sampled true plants of one system and its frequency-wise multiplicative bound.

    Attributes
    ----------
    system : str
        The system's name.
    nominal : LoopSystem or ChannelLoop
        The loop with the model as plant (a vehicle on its own controller: its identified channel map).
    loops : tuple of LoopSystem or ChannelLoop
        One loop per sampled true plant (model unchanged), or per sampled channel map
        (:func:`channel_delta_set`).
    w : array, rad/s
    bound : array
        ``|Delta(jw)|`` bound on ``w`` (3 sigma for identified models).
    rejected : int
        Samples redrawn because their loop was unstable or outside the margin.
    source : str
        ``"identification"`` or ``"fleet bound"``.
    """

    system: str
    nominal: LoopSystem | ChannelLoop
    loops: tuple[LoopSystem | ChannelLoop, ...]
    w: np.ndarray
    bound: np.ndarray
    rejected: int
    source: str

    def __repr__(self) -> str:
        w = np.asarray(self.w)
        span = f"{w.min():.3g}-{w.max():.3g} rad/s" if w.size else "no frequencies"
        return (f"<DeltaSet {self.system!r} ({self.source}): {len(self.loops)} sampled loops, bound max "
                f"{float(np.max(self.bound)) if np.size(self.bound) else 0.0:.3g} on {w.size} frequencies {span}, "
                f"{self.rejected} rejected>")

    def deltas(self, w: np.ndarray | None = None) -> np.ndarray:
        """Multiplicative model errors ``Delta_k(e^{jw Ts}) = P_k / P_hat - 1`` of every sample (of the channel
        map, ``Gf_k / Gf_hat - 1``, for a vehicle on its own controller).

        Parameters
        ----------
        w : array_like, optional
            Frequencies, rad/s (default: :attr:`w`).

        Returns
        -------
        numpy.ndarray
            Complex, ``K x len(w)``.
        """
        w = self.w if w is None else np.asarray(w, float)

        def model(lp):
            return lp.G_f if isinstance(lp, ChannelLoop) else lp.P

        p_hat = freqresp(model(self.nominal), w)
        return np.array([freqresp(model(lp), w) / p_hat - 1 for lp in self.loops])


def _check_samples(k: int) -> None:
    """Refuse a sample count outside 1 to :data:`MAX_DELTA_SAMPLES`."""
    if k < 1 or k > MAX_DELTA_SAMPLES:
        raise SpecError(f"`k` (Delta-set samples per system): got {k}, expected 1 to {MAX_DELTA_SAMPLES}: every sample is "
                        "a closed loop that is built, flown and constrained on by the fir/robust designs")


def _check_bound(bound: float) -> None:
    """Refuse a multiplicative bound outside (0, 1)."""
    if not (np.isfinite(bound) and 0 < bound < 1):
        raise SpecError(f"`bound`: got {bound!r}, expected a relative error in (0, 1)")


#: Aliases on each side of the baseband summed by :func:`sampled_bound`: a map from an acceleration to a position
#: falls at least like ``1/w^2``, so its terms like ``1/k^3`` and the tail beyond 2000 is below ``1e-7`` of the sum.
ALIASES = 2000


def sampled_bound(plant: PlantSpec, ts: float, w: np.ndarray, bound: float) -> np.ndarray:
    """The radius on ``z = e^{jwTs}`` of a stated continuous set ``|Delta(jw)| <= bound`` once plant and model are
    sampled with a zero-order hold (docs/theory.md section 2, "The stated set").

    The sampled response is the sum over the aliases ``w_k = w + 2 pi k / Ts`` of ``a_k = P(j w_k)/(j w_k)``
    (times ``(1 - e^{-jwTs})/Ts``), so the sampled error is ``Delta_d = sum a_k Delta(j w_k) / sum a_k`` and its
    largest size over the set is ``sum |a_k| bound(w_k) / |sum a_k|``, at least ``bound(w)``: equal to it where
    the baseband term dominates, larger towards Nyquist (a relative-degree-4 plant at 2 ms: 0.3 becomes 5 at
    Nyquist). Phases of ``Delta`` at different aliases are independent for a set stated per frequency.

    Parameters
    ----------
    plant : PlantSpec
        The model (``num``, ``den``, ``delay``), continuous.
    ts : float
        Sample time, s.
    w : array_like
        Frequencies in (0, Nyquist), rad/s.
    bound : float
        The stated bound, the same at every frequency.

    Returns
    -------
    numpy.ndarray
        The radius on ``w`` (>= ``bound``).
    """
    w = np.asarray(w, float)
    k = np.arange(-ALIASES, ALIASES + 1)
    s = 1j * (w[:, None] + 2 * np.pi * k[None, :] / ts)
    with np.errstate(all="ignore"):
        a = np.polyval(plant.num, s) / (np.polyval(plant.den, s) * s) * np.exp(-s * plant.delay)
        ratio = np.sum(np.abs(a), axis=1) / np.abs(np.sum(a, axis=1))
    return float(bound) * np.where(np.isfinite(ratio), np.maximum(ratio, 1.0), np.inf)


def _bound_grid(ts: float, w: np.ndarray | None) -> np.ndarray:
    """``w`` (rad/s), or by default 200 log-spaced frequencies from 0.01 rad/s to Nyquist, where a bound is given."""
    return np.logspace(-2, np.log10(0.999 * np.pi / ts), 200) if w is None else np.asarray(w, float)


def _identified_samples(ident: IdentificationSpec, delay: float, rng: np.random.Generator, scale: float):
    """Plants with parameters drawn from the fit's ``N(theta, scale^2 Cov)`` (``delay``: the fit's)."""
    structure = ModelStructure(ident.poles, ident.zeros, ident.integrators)
    theta = np.asarray(ident.parameters)
    cov = np.asarray(ident.covariance) * scale**2
    mean = np.concatenate([theta, [delay]]) if ident.delay_estimated else theta
    fixed = np.diag(cov) == 0  # parameters the fit holds fixed (a zero at s = 0) stay exactly at their value
    while True:
        x = rng.multivariate_normal(mean, cov, method="svd")
        x[fixed] = mean[fixed]
        th, d = (x[:-1], max(0.0, float(x[-1]))) if ident.delay_estimated else (x, delay)
        den, num = structure.split(th)
        yield PlantSpec(tuple(num), tuple(den), d)


def _bound_samples(model: PlantSpec, bound: float, rng: np.random.Generator):
    """Plants ``(1 + Delta) model`` with a gain or first-order high-pass ``Delta``, ``|Delta| <= bound``."""
    while True:
        r = bound * rng.uniform(-1.0, 1.0)
        if rng.uniform() < 0.5:  # gain error
            yield PlantSpec(tuple(np.asarray(model.num) * (1 + r)), model.den, model.delay)
        else:  # high-pass error: P (1 + r s tau/(s tau + 1)), tau log-uniform over TAU_RANGE
            tau = 10 ** rng.uniform(*np.log10(TAU_RANGE))
            num = np.polymul(model.num, [(1 + r) * tau, 1.0])
            den = np.polymul(model.den, [tau, 1.0])
            yield PlantSpec(tuple(num), tuple(den), model.delay)


def delta_set(spec: SystemSpec, ts: float, k: int = 20, rng: np.random.Generator | None = None,
              scale: float = 1.0, bound: float | None = None, w: np.ndarray | None = None,
              max_rejections: int = 200, margin: float = 0.0) -> DeltaSet:
    """Draw ``k`` plausible true plants of ``spec`` (see module docstring).

    Parameters
    ----------
    spec : SystemSpec
    ts : float
        Sample time, s.
    k : int
        Number of samples (>= 1).
    rng : numpy.random.Generator
        Seeded generator (default ``default_rng(0)``).
    scale : float
        Multiplier of the identified standard deviations (1: the identified uncertainty).
    bound : float, optional
        Multiplicative bound to use instead of the fleet file's ``uncertainty.bound`` and the
        identification (in that order of precedence).
    w : array, optional
        Frequencies of the bound, rad/s (default: log grid to Nyquist).
    max_rejections : int
        Sampled plants whose loop is unstable (or outside the margin) are redrawn; more
        rejections than this raise.
    margin : float
        ``m`` in [0, 1): also redraw plants whose disturbance map exceeds ``1/m`` times the
        model's at some frequency (:func:`disturbance_peak`); 0: stability only.

    Returns
    -------
    DeltaSet
        The ``k`` sampled loops and the bound.

    Raises
    ------
    SpecError
        ``k`` outside 1 to :data:`MAX_DELTA_SAMPLES`, no uncertainty to sample from (neither a bound nor an identification), a
        bound outside (0, 1), a bad ``scale`` (:func:`check_scale`), a margin outside [0, 1), or too many rejected
        samples.
    """
    _check_samples(k)
    if not (np.isfinite(margin) and 0 <= margin < 1):
        raise SpecError(f"`margin`: got {margin!r}, expected a number in [0, 1) (0: stability only)")
    rng = np.random.default_rng(0) if rng is None else rng
    nominal = build_loop(spec.exact(), ts)
    found = delta_bound(spec, ts, w, scale, bound)
    if found is None:
        raise SpecError(f"system {spec.name!r}: no identification in the fleet and no `bound` given; "
                        "identify it (ilcdob identify-fleet), state `uncertainty = { bound = 0.2 }` in the "
                        "fleet file, or pass bound=<relative error, e.g. 0.2>")
    w, bnd, source = found
    if source == "fleet bound":  # the stated continuous bound (bnd: its sampled radius)
        gen = _bound_samples(spec.nominal_plant, float(spec.uncertainty.bound if bound is None else bound), rng)
    else:
        gen = _identified_samples(spec.identification, spec.nominal_plant.delay, rng, scale)
    loops, rejected = [], 0
    model = spec.nominal_plant
    peak = _PeakMeter(nominal) if margin > 0 else None
    while len(loops) < k:
        plant = next(gen)
        try:
            loop = build_loop(replace(spec, plant=plant, model=model), ts)
        except (UnstableLoopError, SpecError):
            loop = None
        if loop is not None and (peak is None or peak(loop) <= 1 / margin):
            loops.append(loop)
            continue
        rejected += 1
        if rejected > max_rejections:
            kept = "unstable loops" if margin == 0 else f"unstable loops or |Gd/Gd_hat| > {1 / margin:.3g}"
            raise SpecError(f"system {spec.name!r}: {rejected} sampled plants gave {kept}; the "
                            "uncertainty is too large for this controller (lower `scale` or `bound`)")
    return DeltaSet(spec.name, nominal, tuple(loops), w, bnd, rejected, source)


def channel_delta_set(loop: ChannelLoop, k: int = 8, rng: np.random.Generator | None = None, scale: float = 1.0,
                      bound: float | None = None, w: np.ndarray | None = None,
                      max_rejections: int = 200) -> DeltaSet:
    """Draw ``k`` plausible true channel maps of a vehicle on its own controller (docs/closed_loop.md, "The
    uncertainty set and the check").

    The vehicle is its identified channel map ``G_ch`` (:mod:`ilcdob.channel_loop`): a sample is a map with
    parameters drawn from the fit's ``N(theta, scale^2 Cov)``, or with ``bound`` a map ``(1 + Delta) G_ch``
    with a gain or first-order high-pass error ``|Delta| <= bound`` (as :func:`delta_set` draws a plant), its
    loop rebuilt with the same channel, gain, airframe and add-on DOB. ``Gd`` and ``Gf`` share the error
    (``Gf = K Gd``); samples whose map is unstable are redrawn.

    Parameters
    ----------
    loop : ChannelLoop
        The vehicle as identified.
    k : int
        Number of samples (1 to :data:`MAX_DELTA_SAMPLES`).
    rng : numpy.random.Generator
        Seeded generator (default ``default_rng(0)``).
    scale : float
        Multiplier of the identified standard deviations (1 with ``bound``).
    bound : float, optional
        A common multiplicative bound in (0, 1) instead of the identification.
    w : array, optional
        Frequencies of the bound, rad/s (default: :func:`delta_bound`'s).
    max_rejections : int
        Unstable draws allowed before the set is refused.

    Returns
    -------
    DeltaSet
        ``nominal`` the vehicle, ``loops`` the sampled ones, ``bound`` the 3-sigma (times ``scale``) or stated
        bound on ``w``.

    Raises
    ------
    SpecError
        ``k`` out of range, a bad ``scale`` or ``bound``, no identification and no bound, or too many
        unstable draws.
    """
    _check_samples(k)
    check_scale(scale, bound)
    rng = np.random.default_rng(0) if rng is None else rng
    w = _bound_grid(loop.ts, w)
    g_ch = loop.channel_plant()
    if bound is not None:
        _check_bound(bound)
        gen, source = _bound_samples(g_ch, float(bound), rng), "fleet bound"
        bnd = sampled_bound(g_ch, loop.ts, w, bound)
    else:
        bnd = loop.delta(w, scale)  # raises without an identification
        gen, source = _identified_samples(loop.identification, g_ch.delay, rng, scale), "identification"
    loops, rejected = [], 0
    while len(loops) < k:
        try:
            loops.append(channel_loop(loop.name, loop.ts, loop.channel, next(gen), loop.channel_gain, loop.airframe,
                                      loop.dob, loop.identification, loop.reference_map))
            continue
        except (UnstableLoopError, SpecError):
            rejected += 1
        if rejected > max_rejections:
            raise SpecError(f"vehicle {loop.name!r}: {rejected} sampled channel maps were unstable; the uncertainty "
                            "is too large for this fit (lower `scale` or `bound`)")
    return DeltaSet(loop.name, loop, tuple(loops), w, bnd, rejected, source)


def dense_grid(ts: float, n: int = 20000) -> np.ndarray:
    """Frequencies (rad/s) on which stability and margin limits are sought: 200 log-spaced from 1e-4 rad/s
    below the first of ``n`` linearly spaced to Nyquist (0.008 rad/s apart at 50 Hz with the default).

    Parameters
    ----------
    ts : float
        Sample time, s.
    n : int
        Linear points.

    Returns
    -------
    numpy.ndarray
        Sorted frequencies, rad/s.
    """
    nyq = np.pi / ts
    return np.unique(np.concatenate([np.geomspace(1e-4, nyq / n, 200), np.linspace(nyq / n, nyq, n)]))


#: Linear points of the grid on which the sampler looks for a draw's disturbance peak: 0.04 rad/s apart at
#: 50 Hz, fine for the broad peaks near a margin of 0.5 (the design's limits use 20,000 points and ``0.99 m``,
#: so they contain what this grid keeps); five times faster than the design's grid, for every draw.
_PEAK_POINTS = 4000
_GD_HAT: dict[tuple, np.ndarray] = {}


class _PeakMeter:
    """``max_w |Gd(w)/Gd_hat(w)|`` of true loops around one nominal loop on :func:`dense_grid` of
    :data:`_PEAK_POINTS` (the nominal response computed once per model and sample time)."""

    def __init__(self, nominal: LoopSystem):
        self.w = dense_grid(nominal.ts, _PEAK_POINTS)
        key = (repr(nominal.spec), nominal.ts)
        if key not in _GD_HAT:
            _GD_HAT[key] = freqresp(nominal.G_d, self.w)
        self.gd_hat = _GD_HAT[key]

    def __call__(self, loop: LoopSystem) -> float:
        return float(np.max(np.abs(freqresp(loop.G_d, self.w) / self.gd_hat)))


def disturbance_peak(loop: LoopSystem, nominal: LoopSystem) -> float:
    """``max_w |Gd(w)/Gd_hat(w)|``: how far a true loop's disturbance map leaves its model's, at worst.

    ``Gd`` maps the disturbance to the tracking error (:mod:`ilcdob.loop`); the ratio is what the
    model-based reconstruction of the disturbance from the error is off by (docs/theory.md
    section 3). It grows without bound as the true loop nears its stability boundary.

    Parameters
    ----------
    loop, nominal : LoopSystem
        The true loop and the loop with the model as plant.

    Returns
    -------
    float
        The peak over :func:`dense_grid`.
    """
    return _PeakMeter(nominal)(loop)


def check_scale(scale: object, bound: float | None = None) -> float:
    """``scale`` if it is a factor of the identified standard deviations that applies, else :class:`SpecError`.

    Parameters
    ----------
    scale : object
        The value given: a finite number > 0 (1: the identified uncertainty).
    bound : float, optional
        A common bound given with it: it replaces the identified uncertainty, so ``scale`` must be 1.

    Returns
    -------
    float
    """
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(scale) and scale > 0):
        raise SpecError(f"`scale`: got {scale!r}, expected a factor > 0 of the identified standard deviations "
                        "(1: as identified, 2: twice as wide)")
    if bound is not None and scale != 1:
        raise SpecError(f"`scale`: got {scale!r} with `bound` {bound!r}: the bound replaces the identified uncertainty "
                        "that scale multiplies; give one of them")
    return float(scale)


def delta_bound(spec: SystemSpec, ts: float, w: np.ndarray | None = None, scale: float = 1.0,
                bound: float | None = None) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The frequency-wise bound ``|Delta(jw)|`` of a system's Delta set, without sampling plants.

    Same precedence as :func:`delta_set`: ``bound``, then the fleet file's
    ``uncertainty.bound``, then the identification's 3-sigma bound (times ``scale``).

    Parameters
    ----------
    spec : SystemSpec
    ts : float
        Sample time, s.
    w : array, optional
        Frequencies, rad/s (default: 200 log-spaced points from 0.01 rad/s to Nyquist).
    scale : float
        Multiplier (> 0) of the identified standard deviations; 1 with a given ``bound``, which
        replaces the identified uncertainty it would multiply.
    bound : float, optional
        A common multiplicative bound in (0, 1).

    Returns
    -------
    (w, bound, source) or None
        Frequencies, the bound on them and ``"fleet bound"`` or ``"identification"``; None
        when the system has neither a bound nor an identification. A stated bound is the
        continuous one: its radius on the sampled plant (:func:`sampled_bound`) is returned.

    Raises
    ------
    SpecError
        ``scale`` not a finite number > 0, or other than 1 with a given ``bound``; ``bound``
        outside (0, 1).
    """
    check_scale(scale, bound)
    w = _bound_grid(ts, w)
    if bound is None and spec.uncertainty is not None:
        bound = spec.uncertainty.bound
    if bound is not None:
        _check_bound(bound)
        return w, sampled_bound(spec.nominal_plant, ts, w, float(bound)), "fleet bound"
    ident = spec.identification
    if ident is None:
        return None
    bnd = scale * ident.bound(w, spec.nominal_plant.delay)
    return w, bnd, "identification"
