"""Experiment design: excitation signals for identification flights.

* :class:`StepSequence` -- a staircase of set-points (m, or m/s^2 for an acceleration
  input), each held for ``hold`` s, optionally joined by linear ramps;
* :class:`Chirp` -- a swept sine from ``f0`` to ``f1`` Hz, linear or logarithmic sweep,
  with raised-cosine fade-in/out;
* :func:`suggest_band` / :func:`suggest_band_for_loop` -- which frequencies a chirp should
  cover, from the closed-loop bandwidth (:func:`closed_loop_bandwidth`);
* :func:`write_setpoint_csv` -- a CSV file a flight computer can play back, in the same
  format as :meth:`FlightData.to_csv <ilcdob.signals.FlightData.to_csv>`.

Time is in s from the start of the experiment (``t = 0``), frequencies in Hz unless a
name ends in ``_rad_s``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy.optimize import brentq

from ilcdob.errors import SignalError, SpecError
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.signals import FlightData, check_grid


__all__ = [
    "StepSequence",
    "Chirp",
    "suggest_band",
    "suggest_band_for_loop",
    "closed_loop_bandwidth",
    "write_setpoint_csv",
    "BAND_LOW_FACTOR",
    "BAND_HIGH_FACTOR",
    "NYQUIST_FRACTION",
]

#: Lower edge of a suggested chirp band, as a fraction of the closed-loop bandwidth.
BAND_LOW_FACTOR = 0.1
#: Upper edge of a suggested chirp band, as a multiple of the closed-loop bandwidth.
BAND_HIGH_FACTOR = 4.0
#: A suggested band stops at this fraction of the Nyquist frequency ``1 / (2 ts)``.
NYQUIST_FRACTION = 0.8


def _finite(name: str, value: Any, owner: str) -> float:
    if isinstance(value, bool):
        raise SpecError(f"{owner}: `{name}`: got {value!r}, expected a number")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SpecError(f"{owner}: `{name}`: got {value!r}, expected a number") from None
    if not math.isfinite(v):
        raise SpecError(f"{owner}: `{name}`: got {value!r}, expected a finite number")
    return v


def _time_array(t: Any, owner: str) -> np.ndarray:
    arr = np.asarray(t, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise SignalError(f"{owner}.signal: `t`: non-finite time stamps; expected finite times in s")
    return arr


@dataclass(frozen=True)
class StepSequence:
    """A staircase of set-points.

    Level ``k`` occupies ``k * hold <= t < (k + 1) * hold``; with ``ramp > 0`` the first
    ``ramp`` s of each level after the first are a straight line from the previous level.
    Before ``t = 0`` the signal is ``levels[0]``, after :attr:`duration` it stays at
    ``levels[-1]``.

    Attributes
    ----------
    levels : tuple of float
        Set-point levels, in the unit of the signal they drive (m for a position
        reference, m/s^2 for an acceleration input).
    hold : float
        Time each level lasts, s (> 0).
    ramp : float
        Duration of the linear transition into each level, s (``0 <= ramp < hold``).
    """

    levels: tuple[float, ...]
    hold: float
    ramp: float = 0.0

    def __post_init__(self) -> None:
        owner = "StepSequence"
        if isinstance(self.levels, (str, bytes)) or not hasattr(self.levels, "__len__"):
            raise SpecError(f"{owner}: `levels`: got {self.levels!r}, expected a tuple of numbers")
        if len(self.levels) == 0:
            raise SpecError(f"{owner}: `levels`: empty; expected at least one level")
        levels = tuple(_finite(f"levels[{i}]", v, owner) for i, v in enumerate(self.levels))
        hold = _finite("hold", self.hold, owner)
        if hold <= 0:
            raise SpecError(f"{owner}: `hold`: got {self.hold!r}, expected a duration > 0 (s)")
        ramp = _finite("ramp", self.ramp, owner)
        if not 0 <= ramp < hold:
            raise SpecError(f"{owner}: `ramp`: got {self.ramp!r}, expected 0 <= ramp < hold = {hold!r} (s)")
        object.__setattr__(self, "levels", levels)
        object.__setattr__(self, "hold", hold)
        object.__setattr__(self, "ramp", ramp)

    @property
    def duration(self) -> float:
        """``len(levels) * hold``, s."""
        return len(self.levels) * self.hold

    def signal(self, t: np.ndarray) -> np.ndarray:
        """The set-point at given times.

        Parameters
        ----------
        t : array_like
            Times, s (any shape).

        Returns
        -------
        numpy.ndarray
            The set-point, same shape as ``t``.
        """
        t = _time_array(t, "StepSequence")
        lv = np.asarray(self.levels)
        k = np.clip(np.floor(t / self.hold).astype(int), 0, lv.size - 1)
        x = lv[k]
        if self.ramp > 0 and lv.size > 1:
            tau = t - k * self.hold
            on_ramp = (k >= 1) & (tau < self.ramp) & (t < self.duration)
            prev = lv[np.maximum(k - 1, 0)]
            frac = np.clip(tau / self.ramp, 0.0, 1.0)
            x = np.where(on_ramp, prev + (lv[k] - prev) * frac, x)
        return x

    def sample(self, ts: float) -> tuple[np.ndarray, np.ndarray]:
        """The staircase sampled on the grid ``t = k ts`` covering ``[0, duration]``.

        Parameters
        ----------
        ts : float
            Sample time, s (> 0, not longer than the duration).

        Returns
        -------
        t : numpy.ndarray
            Times, s.
        x : numpy.ndarray
            The set-point at ``t``.
        """
        t = _grid(ts, self.duration, "StepSequence")
        return t, self.signal(t)


@dataclass(frozen=True)
class Chirp:
    """Swept sine ``amplitude * w(t) * sin(phi(t))`` for ``0 <= t <= duration`` (0 outside).

    Instantaneous frequency ``f(t) = phi'(t) / (2 pi)``:

    * ``sweep="linear"``: ``f(t) = f0 + (f1 - f0) t / T``,
      ``phi(t) = 2 pi (f0 t + (f1 - f0) t^2 / (2 T))``;
    * ``sweep="log"`` (exponential): ``f(t) = f0 (f1/f0)^(t/T)``,
      ``phi(t) = 2 pi f0 T (k^(t/T) - 1) / ln k`` with ``k = f1/f0`` -- the same time
      per octave, which suits Bode plots.

    ``w(t)`` is a raised-cosine fade: ``(1 - cos(pi t / fade)) / 2`` over the first
    ``fade`` s, mirrored over the last ``fade`` s, 1 in between (no step at the start or
    end, which would excite frequencies outside the band).

    Attributes
    ----------
    f0, f1 : float
        Start and end frequency, Hz (``f0 >= 0``, ``f1 > 0``, ``f0 != f1``; ``f0 > 0`` for a
        log sweep; a down-sweep ``f1 < f0`` is allowed).
    duration : float
        Sweep length ``T``, s (> 0).
    amplitude : float
        Peak value (> 0), in the unit of the driven signal (m or m/s^2).
    sweep : {"linear", "log"}
        Linear or exponential sweep.
    fade : float
        Raised-cosine fade-in and fade-out length, s (``0 <= fade <= duration / 2``).
    ts : float, optional
        Sample time the chirp will be played at, s; when given, ``max(f0, f1)`` must lie
        below the Nyquist frequency ``1 / (2 ts)``.
    """

    f0: float
    f1: float
    duration: float
    amplitude: float
    sweep: str = "linear"
    fade: float = 0.0
    ts: float | None = None

    def __post_init__(self) -> None:
        owner = "Chirp"
        f0 = _finite("f0", self.f0, owner)
        f1 = _finite("f1", self.f1, owner)
        dur = _finite("duration", self.duration, owner)
        amp = _finite("amplitude", self.amplitude, owner)
        fade = _finite("fade", self.fade, owner)
        if self.sweep not in ("linear", "log"):
            raise SpecError(f"{owner}: `sweep`: got {self.sweep!r}, expected 'linear' or 'log'")
        if f0 < 0:
            raise SpecError(f"{owner}: `f0`: got {self.f0!r}, expected a frequency >= 0 (Hz)")
        if self.sweep == "log" and f0 <= 0:
            raise SpecError(f"{owner}: `f0`: got {self.f0!r}, expected f0 > 0 (Hz) for a log sweep "
                            f"(the log of 0 is undefined); use sweep='linear' to start at 0 Hz")
        if f1 <= 0:
            raise SpecError(f"{owner}: `f1`: got {self.f1!r}, expected a frequency > 0 (Hz)")
        if f1 == f0:
            raise SpecError(f"{owner}: `f1`: got {self.f1!r} = f0; expected f1 != f0 (a chirp sweeps)")
        if dur <= 0:
            raise SpecError(f"{owner}: `duration`: got {self.duration!r}, expected a duration > 0 (s)")
        if amp <= 0:
            raise SpecError(f"{owner}: `amplitude`: got {self.amplitude!r}, expected a peak value > 0")
        if not 0 <= fade <= dur / 2:
            raise SpecError(f"{owner}: `fade`: got {self.fade!r}, expected 0 <= fade <= duration/2 = "
                            f"{dur / 2!r} (s)")
        ts = None
        if self.ts is not None:
            ts = _finite("ts", self.ts, owner)
            if ts <= 0:
                raise SpecError(f"{owner}: `ts`: got {self.ts!r}, expected a sample time > 0 (s)")
            nyq = 0.5 / ts
            for name, f in (("f0", f0), ("f1", f1)):
                if f >= nyq:
                    raise SpecError(f"{owner}: `{name}`: got {f!r} Hz, expected below the Nyquist frequency "
                                    f"1/(2 ts) = {nyq:.6g} Hz for ts = {ts!r} s")
        for name, v in (("f0", f0), ("f1", f1), ("duration", dur), ("amplitude", amp), ("fade", fade),
                        ("ts", ts)):
            object.__setattr__(self, name, v)

    def frequency(self, t: np.ndarray) -> np.ndarray:
        """Instantaneous frequency ``f(t)``.

        Parameters
        ----------
        t : array_like
            Times, s; clipped to ``[0, duration]``.

        Returns
        -------
        numpy.ndarray
            ``f(t)``, Hz.
        """
        tau = np.clip(_time_array(t, "Chirp"), 0.0, self.duration) / self.duration
        if self.sweep == "linear":
            return self.f0 + (self.f1 - self.f0) * tau
        return self.f0 * (self.f1 / self.f0) ** tau

    def phase(self, t: np.ndarray) -> np.ndarray:
        """Phase ``phi(t)``.

        Parameters
        ----------
        t : array_like
            Times, s; clipped to ``[0, duration]``.

        Returns
        -------
        numpy.ndarray
            ``phi(t)``, rad.
        """
        tt = np.clip(_time_array(t, "Chirp"), 0.0, self.duration)
        T = self.duration
        if self.sweep == "linear":
            return 2 * np.pi * (self.f0 * tt + (self.f1 - self.f0) * tt**2 / (2 * T))
        lk = math.log(self.f1 / self.f0)
        return 2 * np.pi * self.f0 * T * np.expm1(lk * tt / T) / lk

    def envelope(self, t: np.ndarray) -> np.ndarray:
        """Fade window ``w(t)``.

        Parameters
        ----------
        t : array_like
            Times, s.

        Returns
        -------
        numpy.ndarray
            ``w(t)`` in [0, 1] (0 outside ``[0, duration]``).
        """
        t = _time_array(t, "Chirp")
        w = ((t >= 0) & (t <= self.duration)).astype(float)
        if self.fade > 0:
            rise = np.clip(t / self.fade, 0.0, 1.0)
            fall = np.clip((self.duration - t) / self.fade, 0.0, 1.0)
            w = w * 0.5 * (1 - np.cos(np.pi * np.minimum(rise, fall)))
        return w

    def signal(self, t: np.ndarray) -> np.ndarray:
        """The chirp at given times.

        Parameters
        ----------
        t : array_like
            Times, s (any shape).

        Returns
        -------
        numpy.ndarray
            ``amplitude * w(t) * sin(phi(t))``, same shape as ``t``.
        """
        return self.amplitude * self.envelope(t) * np.sin(self.phase(t))

    def sample(self, ts: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The chirp sampled on the grid ``t = k ts`` covering ``[0, duration]``.

        Parameters
        ----------
        ts : float, optional
            Sample time, s (default: the field ``ts``); checked against Nyquist like the field.

        Returns
        -------
        t : numpy.ndarray
            Times, s.
        x : numpy.ndarray
            The chirp at ``t``.

        Raises
        ------
        SpecError
            No sample time, or one too long for the chirp's frequencies or duration.
        """
        ts = self.ts if ts is None else ts
        if ts is None:
            raise SpecError("Chirp.sample: `ts`: not given and the chirp has no `ts`; give a sample time > 0 (s)")
        if self.ts is None or ts != self.ts:
            Chirp(self.f0, self.f1, self.duration, self.amplitude, self.sweep, self.fade, ts)  # validates
        t = _grid(ts, self.duration, "Chirp")
        return t, self.signal(t)


def _grid(ts: float, duration: float, owner: str) -> np.ndarray:
    ts = _finite("ts", ts, owner)
    if ts <= 0:
        raise SpecError(f"{owner}.sample: `ts`: got {ts!r}, expected a sample time > 0 (s)")
    check_grid(duration, ts, f"{owner}.sample")
    n = int(math.floor(duration / ts + 1e-9)) + 1
    if n < 2:
        raise SpecError(f"{owner}.sample: `ts`: got {ts!r} s, longer than the duration {duration!r} s")
    return np.arange(n) * ts


def suggest_band(bandwidth_rad_s: float, ts: float | None = None) -> tuple[float, float]:
    """Chirp band ``(f_lo, f_hi)`` in Hz for a loop of closed-loop bandwidth ``bandwidth_rad_s``.

    Rule: with ``f_b = bandwidth_rad_s / (2 pi)`` (Hz), ``f_lo = BAND_LOW_FACTOR * f_b``
    (0.1: a decade below, where the loop tracks and the low-frequency gain is pinned down)
    and ``f_hi = BAND_HIGH_FACTOR * f_b`` (4: within the usual 3-5x, past the roll-off,
    where the plant's high-frequency poles and the delay show). With a sample time ``ts``
    the upper edge is capped at ``NYQUIST_FRACTION / (2 ts)`` (0.8 of Nyquist).

    Parameters
    ----------
    bandwidth_rad_s : float
        Closed-loop -3 dB bandwidth, rad/s (> 0).
    ts : float, optional
        Sample time of the experiment, s.

    Returns
    -------
    (float, float)
        ``(f_lo, f_hi)``, Hz.

    Raises
    ------
    SpecError
        Non-positive or non-finite input, or a cap at Nyquist that leaves no band
        (``f_hi <= f_lo``).
    """
    wb = _finite("bandwidth_rad_s", bandwidth_rad_s, "suggest_band")
    if wb <= 0:
        raise SpecError(f"suggest_band: `bandwidth_rad_s`: got {bandwidth_rad_s!r}, expected a bandwidth > 0 (rad/s)")
    fb = wb / (2 * np.pi)
    lo, hi = BAND_LOW_FACTOR * fb, BAND_HIGH_FACTOR * fb
    if ts is not None:
        ts_f = _finite("ts", ts, "suggest_band")
        if ts_f <= 0:
            raise SpecError(f"suggest_band: `ts`: got {ts!r}, expected a sample time > 0 (s)")
        hi = min(hi, NYQUIST_FRACTION * 0.5 / ts_f)
        if hi <= lo:
            raise SpecError(f"suggest_band: bandwidth {wb:.6g} rad/s ({fb:.6g} Hz) is too high for ts = {ts!r} s: "
                            f"the band would start at {lo:.6g} Hz, above {NYQUIST_FRACTION} x Nyquist = "
                            f"{hi:.6g} Hz; sample faster")
    return float(lo), float(hi)


def closed_loop_bandwidth(sys: Any, name: str = "system") -> float:
    """-3 dB bandwidth of a discrete SISO map, rad/s.

    The lowest frequency at which ``|G(e^{j w ts})|`` falls to ``|G(1)| / sqrt(2)`` (its
    DC gain less 3 dB), found on a logarithmic grid up to Nyquist and refined by Brent's
    method (relative accuracy 1e-10). Resonant peaking above the DC gain before the
    roll-off is passed over.

    Parameters
    ----------
    sys : control.StateSpace or control.TransferFunction
        Discrete-time (``sys.dt > 0``), e.g. ``loop.G_r``.
    name : str
        Used in error messages.

    Raises
    ------
    SpecError
        Continuous-time system, zero DC gain, or no -3 dB crossing below Nyquist.
    """
    dt = getattr(sys, "dt", None)
    if dt is None or dt is True or not (isinstance(dt, (int, float)) and dt > 0):
        raise SpecError(f"closed_loop_bandwidth: {name}: got dt = {dt!r}, expected a discrete system with dt > 0 (s)")
    dt = float(dt)
    g0 = abs(complex(np.asarray(sys(1.0)).reshape(-1)[0]))
    if not (np.isfinite(g0) and g0 > 0):
        raise SpecError(f"closed_loop_bandwidth: {name}: DC gain |G(1)| = {g0!r}; expected a finite gain > 0")
    target = g0 / math.sqrt(2.0)
    w_nyq = math.pi / dt
    w = np.logspace(math.log10(w_nyq) - 6, math.log10(w_nyq), 3000)
    mag = np.abs(freqresp(sys, w))
    below = np.flatnonzero(mag < target)
    if below.size == 0:
        raise SpecError(f"closed_loop_bandwidth: {name}: |G| stays above -3 dB of its DC gain up to Nyquist "
                        f"({w_nyq:.6g} rad/s); no bandwidth below the sampling limit")
    k = int(below[0])
    if k == 0:
        raise SpecError(f"closed_loop_bandwidth: {name}: |G| already below -3 dB of its DC gain at "
                        f"{w[0]:.3g} rad/s; expected a low-pass map")

    def f(x: float) -> float:
        return float(abs(freqresp(sys, np.array([x]))[0])) - target

    return float(brentq(f, w[k - 1], w[k], xtol=1e-14, rtol=1e-10))


def suggest_band_for_loop(loop: LoopSystem) -> tuple[float, float]:
    """:func:`suggest_band` for the reference-to-position map ``G_r`` of ``loop``.

    The bandwidth is :func:`closed_loop_bandwidth` of ``loop.G_r`` (rad/s); the upper edge
    is capped at ``NYQUIST_FRACTION`` of the loop's Nyquist frequency ``1 / (2 loop.ts)``.

    Parameters
    ----------
    loop : LoopSystem
        The system's loop (from :func:`ilcdob.build_loop` or ``fleet.loops``).

    Returns
    -------
    (float, float)
        ``(f_lo, f_hi)``, Hz.
    """
    if not isinstance(loop, LoopSystem):
        raise SpecError(f"suggest_band_for_loop: `loop`: got {type(loop).__name__}, expected an ilcdob.LoopSystem "
                        f"(from ilcdob.build_loop or fleet.loops)")
    wb = closed_loop_bandwidth(loop.G_r, f"system {loop.name!r} G_r")
    return suggest_band(wb, ts=loop.ts)


def write_setpoint_csv(path: str | os.PathLike, t: np.ndarray, *, units: Mapping[str, str] | None = None,
                       **signals: np.ndarray) -> FlightData:
    """Write set-points as a CSV a flight computer can play back.

    The format is :meth:`FlightData.to_csv`: a comment line ``# units: time=s, name=unit,
    ...``, a header row ``time,name,...``, then one row per sample (10 significant digits);
    the file is written atomically. :func:`~ilcdob.identification.loaders.load_csv` reads it
    back.

    Parameters
    ----------
    path : str or os.PathLike
    t : numpy.ndarray
        Uniform, strictly increasing time stamps, s.
    units : dict of str -> str, optional
        Unit of each signal (e.g. ``{"x_ref": "m"}``); "" where not given.
    **signals : numpy.ndarray
        One column each, the same length as ``t`` (so no signal can be called ``units``).

    Returns
    -------
    FlightData
        What was written.

    Raises
    ------
    SignalError
        No signals, non-uniform or non-increasing ``t``, a length mismatch or non-finite
        values (the message names the file and the signal).
    """
    source = os.fspath(path)
    if not signals:
        raise SignalError(f"{source}: no signals given; pass them as keywords, e.g. x_ref=x")
    if "time" in signals:
        raise SignalError(f"{source}: the signal name 'time' is reserved for the time column")
    units = dict(units or {})
    unknown = sorted(set(units) - set(signals))
    if unknown:
        raise SignalError(f"{source}: `units`: unknown signal(s) {unknown}; signals: {sorted(signals)}")
    fd = FlightData(np.asarray(t, dtype=float), dict(signals), units, {"kind": "setpoint"}, source)
    fd.to_csv(source)
    return fd
