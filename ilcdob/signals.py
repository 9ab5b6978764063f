"""One flight-data object for every source (CSV, Parquet, PX4 ULog, ArduPilot DataFlash,
and the synthetic flights).

Conventions: time in s on a uniform grid starting wherever the log starts; every signal is
a 1-D float array of the same length as ``t``; ``units`` maps a signal name to its unit
string (e.g. ``"m"``, ``"m/s^2"``). Constructing a :class:`FlightData` checks all of it and
raises :class:`~ilcdob.errors.SignalError` naming the source and the signal.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .atomic import atomic_path
from .display import html_table, time_text
from .errors import SignalError, SpecError
from .names import csv_field

__all__ = ["FlightData", "as_signal", "check_time", "check_signal", "check_grid", "extend_smoothly",
           "resample_onto", "segments", "MIN_WINDOW_SAMPLES", "MAX_GRID_SAMPLES", "SAMPLE_GAP_FACTOR"]

#: Relative tolerance on the spacing of a "uniform" time grid.
UNIFORM_RTOL = 1e-6

#: A step between two time stamps of a signal longer than this many median steps is a gap
#: (a dropout of the logger): :meth:`FlightData.from_samples` records it in
#: ``metadata["gaps"]`` and :meth:`FlightData.pieces` cuts the record there, instead of
#: fitting a model to the straight line that interpolation draws across it.
GAP_FACTOR = 5.0

#: A step between two time stamps of a signal longer than this many median steps has at least one
#: sample missing: :meth:`FlightData.from_samples` records every such step in
#: ``metadata["sample_gaps"]`` (beside the :data:`GAP_FACTOR` gaps, where identification cuts),
#: and a trial to learn from, which must hold a sample at every ``k Ts``, is refused with any
#: (:meth:`FlightData.missing_samples`). 1.5 is midway between a step of the log (1) and a step
#: with one sample missing (2): a logger's jitter moves a stamp by a few percent of a step (a late
#: stamp makes one step longer and the next shorter by as much), so the steps of a complete log
#: stay far below it, and a step over a missing sample stays above it until the jitter reaches
#: half a step.
SAMPLE_GAP_FACTOR = 1.5

#: Most samples one time grid (a trial, a flight, a resampled log, a wind series) may hold: 5 million,
#: 83 min at 1 ms, the shortest sample time the designs are tested at (the scenarios last 40 to 60 s:
#: 60,000 samples at 1 ms, 1.5 million at a 10 kHz loop). A longer grid comes from a sample time or a
#: duration in the wrong unit, and is refused (:func:`check_grid`) before anything is allocated: a
#: flight holds about ten signals of 8 bytes a sample, 400 MB at this bound.
MAX_GRID_SAMPLES = 5_000_000

#: Fewest samples a window of :func:`segments` may hold.
MIN_WINDOW_SAMPLES = 10


def as_signal(x: object, name: str, n: int | None = None) -> np.ndarray:
    """Check the signal convention: a 1-D finite float array (of length ``n`` if given).

    The convention (stated once in :mod:`ilcdob`, checked at every entry): one sample per
    sample time ``Ts`` on the grid ``t = k Ts``.

    Parameters
    ----------
    x : array_like
        The samples.
    name : str
        The argument's name, for the error message.
    n : int, optional
        Required number of samples.

    Returns
    -------
    numpy.ndarray
        ``x`` as a 1-D float array.

    Raises
    ------
    SignalError
        Not 1-D, the wrong length, or a non-finite sample (the message names the first).
    """
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 1:
        raise SignalError(f"`{name}`: expected a 1-D array of samples, got shape {arr.shape}")
    if n is not None and arr.size != n:
        raise SignalError(f"`{name}`: expected {n} samples, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise SignalError(f"`{name}`: non-finite value {arr[bad]!r} at sample {bad}")
    return arr


def extend_smoothly(x: np.ndarray, n_pad: int, n_fit: int = 16) -> np.ndarray:
    """Continue a trial smoothly past its end: a cubic fitted to its last samples, extrapolated.

    Used where a non-causal filter looks ahead of the recorded trial (docs/theory.md
    section 2: the anti-causal part of a stable inversion runs backwards from beyond the end).

    Parameters
    ----------
    x : numpy.ndarray
        The trial (1-D).
    n_pad : int
        Number of samples to append (nothing is appended when ``<= 0``).
    n_fit : int
        Number of final samples the polynomial is fitted to (degree ``min(3, n_fit - 1)``;
        fewer when ``x`` is shorter).

    Returns
    -------
    numpy.ndarray
        ``x`` followed by ``n_pad`` extrapolated samples (``x`` itself when ``n_pad <= 0``).
    """
    if n_pad <= 0:
        return x
    m = min(n_fit, x.size)
    deg = min(3, m - 1)
    k = np.arange(m, dtype=float)
    coef = np.polyfit(k, x[-m:], deg) if deg > 0 else np.array([x[-1]])
    return np.concatenate([x, np.polyval(coef, np.arange(m, m + n_pad, dtype=float))])


def check_time(t: np.ndarray, source: str, signal: str = "time") -> np.ndarray:
    """Check time stamps: at least two, finite, strictly increasing (no duplicates).

    Parameters
    ----------
    t : array_like
        Time stamps, s (not necessarily uniform).
    source : str
        File or description the stamps came from, for the error message.
    signal : str
        Name of the time column, for the error message.

    Returns
    -------
    numpy.ndarray
        ``t`` as a 1-D float array.

    Raises
    ------
    SignalError
        Fewer than two stamps, a non-finite, duplicated or decreasing one (the message names
        the first and its sample).
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise SignalError(f"{source}: `{signal}`: expected at least 2 time stamps, got shape {t.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise SignalError(f"{source}: `{signal}`: non-finite time stamp {float(t[bad[0]])!r} at sample {bad[0]}")
    dt = np.diff(t)
    if np.any(dt == 0):
        k = int(np.flatnonzero(dt == 0)[0])
        raise SignalError(f"{source}: `{signal}`: duplicated time stamp {float(t[k])!r} at samples {k} and {k + 1}")
    if np.any(dt < 0):
        k = int(np.flatnonzero(dt < 0)[0])
        raise SignalError(f"{source}: `{signal}`: time stamps not increasing at sample {k + 1} "
                          f"({float(t[k])!r} -> {float(t[k + 1])!r})")
    return t


def check_grid(duration: float, ts: float, what: str) -> None:
    """Check the length of a time grid before it is allocated: ``duration / ts`` samples, at most
    :data:`MAX_GRID_SAMPLES`.

    Parameters
    ----------
    duration : float
        Length of the grid, s.
    ts : float
        Its sample time, s (> 0).
    what : str
        What the grid is for, for the message (e.g. ``"scenario 1"``).

    Raises
    ------
    SpecError
        ``duration / ts`` is more than :data:`MAX_GRID_SAMPLES`, or not a number, or ``ts <= 0``: the
        message names the sample time, the duration, the number of samples and the bound.
    """
    duration, ts = float(duration), float(ts)
    n = duration / ts if ts > 0 else np.inf
    if not n <= MAX_GRID_SAMPLES:
        raise SpecError(f"{what}: a duration of {duration:g} s at a sample time of {ts:g} s is {n:.4g} samples; "
                        f"expected at most {MAX_GRID_SAMPLES:,} samples a trial ({MAX_GRID_SAMPLES * ts:.4g} s at "
                        "this sample time; a sample time of 1 ms to 50 ms is what ilcdob is built for): check that "
                        "the sample time and the duration are in s")


def check_signal(x: object, t: np.ndarray, source: str, name: str) -> np.ndarray:
    """A signal as a float array with one finite value per time stamp in ``t``.

    Parameters
    ----------
    x : array_like
        The signal's samples.
    t : numpy.ndarray
        Its (checked) time stamps, s.
    source : str
        File or description the signal came from, for the error message.
    name : str
        The signal's name, for the error message.

    Returns
    -------
    numpy.ndarray
        ``x`` as a float array of the shape of ``t``.

    Raises
    ------
    SignalError
        A different shape, or a non-finite value (the message names its time).
    """
    arr = np.asarray(x, dtype=float)
    if arr.shape != t.shape:
        raise SignalError(f"{source}: signal `{name}`: expected {t.size} samples, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise SignalError(f"{source}: signal `{name}`: non-finite value {float(arr[bad[0]])!r} at "
                          f"t = {time_text(t[bad[0]])} s (sample {bad[0]})")
    return arr


def _merge_intervals(intervals: list[list[float]], touching: bool = True) -> list[list[float]]:
    """Overlapping intervals merged (and, with ``touching``, those sharing an end)."""
    out: list[list[float]] = []
    for lo, hi in sorted(intervals):
        if out and (lo <= out[-1][1] if touching else lo < out[-1][1]):
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return out


def resample_onto(t_src: np.ndarray, x: np.ndarray, t_new: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x(t_src)`` onto ``t_new`` (inside the source span).

    Parameters
    ----------
    t_src : numpy.ndarray
        Time stamps of ``x``, s, increasing.
    x : numpy.ndarray
        The signal.
    t_new : numpy.ndarray
        Time stamps wanted, s; outside ``t_src``'s span the end values are held.

    Returns
    -------
    numpy.ndarray
        The signal at ``t_new``.
    """
    return np.interp(t_new, t_src, x)


#: Largest denominator of the rational factor :meth:`FlightData.resampled` accepts between two sample times.
RESAMPLE_MAX_DENOMINATOR = 1000


@dataclass(frozen=True)
class FlightData:
    """Named signals of one flight (or experiment) on a uniform time grid.

    Attributes
    ----------
    t : numpy.ndarray
        Time stamps, s, uniform spacing ``ts``.
    signals : dict of str -> numpy.ndarray
        Each the same length as ``t``.
    units : dict of str -> str
        Unit of each signal ("" where unknown).
    metadata : dict
        Free-form (vehicle, experiment, sample rates of the original topics, ...).
    source : str
        File name or description, used in every error message.
    """

    t: np.ndarray
    signals: dict[str, np.ndarray]
    units: dict[str, str] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    source: str = "<memory>"

    def __post_init__(self) -> None:
        t = check_time(self.t, self.source)
        dt = np.diff(t)
        if np.max(np.abs(dt - dt[0])) > UNIFORM_RTOL * dt[0] + 1e-12:
            raise SignalError(f"{self.source}: signal `time`: not uniformly spaced (steps from {dt.min():.6g} "
                              f"to {dt.max():.6g} s); resample first (FlightData.from_samples)")
        sig = {name: check_signal(x, t, self.source, name) for name, x in self.signals.items()}
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "signals", sig)
        object.__setattr__(self, "units", {n: self.units.get(n, "") for n in sig})

    @classmethod
    def from_samples(cls, series: dict[str, tuple[np.ndarray, np.ndarray]], ts: float | None = None,
                     units: dict[str, str] | None = None, metadata: dict[str, Any] | None = None,
                     source: str = "<memory>") -> "FlightData":
        """Build from signals with their own time stamps (mixed rates), resampled onto one grid.

        The common grid spans the overlap of all signals; each signal is interpolated linearly
        onto it. Steps longer than :data:`GAP_FACTOR` median steps of a signal are recorded as
        gaps (``metadata["gaps"]``: ``[t_before, t_after]`` pairs, s), and steps longer than
        :data:`SAMPLE_GAP_FACTOR` median steps, each with a sample or more missing, as
        ``metadata["sample_gaps"]`` (the same pairs; :meth:`missing_samples`).

        Parameters
        ----------
        series : dict of str to (numpy.ndarray, numpy.ndarray)
            Signal name -> ``(t, x)``: its own strictly increasing time stamps (s) and samples.
        ts : float, optional
            Sample time of the common grid; default: the finest median step among the signals.
        units : dict of str to str, optional
            Unit of each signal.
        metadata : dict, optional
            Free-form; ``original_rates_hz`` (each signal's median rate) is added unless given,
            and ``gaps`` and ``sample_gaps`` when there are any.
        source : str
            File name or description, for messages.

        Returns
        -------
        FlightData
            The resampled flight.

        Raises
        ------
        SignalError
            No signals, bad time stamps or samples, a bad ``ts``, signals that do not overlap in
            time, or a grid of more than :data:`MAX_GRID_SAMPLES` samples.
        """
        if not series:
            raise SignalError(f"{source}: no signals given")
        checked = {}
        for name, (t, x) in series.items():
            t = check_time(t, source, f"time of {name}")
            checked[name] = (t, check_signal(x, t, source, name))
        if ts is None:
            ts = min(float(np.median(np.diff(t))) for t, _ in checked.values())
        if not (np.isfinite(ts) and ts > 0):
            raise SignalError(f"{source}: `ts`: got {ts!r}, expected a sample time > 0 (s)")
        t0 = max(t[0] for t, _ in checked.values())
        t1 = min(t[-1] for t, _ in checked.values())
        if t1 <= t0:
            raise SignalError(f"{source}: the signals {sorted(checked)} do not overlap in time")
        if not (t1 - t0) / ts <= MAX_GRID_SAMPLES:  # before the grid is allocated
            raise SignalError(f"{source}: the common time grid of the signals {sorted(checked)}, {t0:.6g} to "
                              f"{t1:.6g} s at a step of {ts:g} s (`ts`, else the finest median step of a signal), "
                              f"is {(t1 - t0) / ts:.4g} samples; expected at most {MAX_GRID_SAMPLES:,}: give a "
                              "longer `ts`, cut the log with start/stop, or check the unit of the time stamps")
        grid = t0 + np.arange(int(np.floor((t1 - t0) / ts + 1e-9)) + 1) * ts
        rates = {name: 1.0 / float(np.median(np.diff(t))) for name, (t, _) in checked.items()}
        meta = dict(metadata or {})
        meta.setdefault("original_rates_hz", rates)
        gaps, missing = [], []
        for t, _ in checked.values():
            dt = np.diff(t)
            step = np.median(dt)
            gaps += [[float(t[k]), float(t[k + 1])] for k in np.flatnonzero(dt > GAP_FACTOR * step)]
            missing += [[float(t[k]), float(t[k + 1])] for k in np.flatnonzero(dt > SAMPLE_GAP_FACTOR * step)]
        if gaps:
            meta["gaps"] = _merge_intervals(gaps)
        if missing:  # two gaps around one sample stay two
            meta["sample_gaps"] = _merge_intervals(missing, touching=False)
        return cls(t=grid, signals={n: resample_onto(t, x, grid) for n, (t, x) in checked.items()},
                   units=dict(units or {}), metadata=meta, source=source)

    def __repr__(self) -> str:
        source = self.source if len(self.source) <= 40 else "..." + self.source[-37:]
        names = [f"{n if len(n) <= 32 else n[:29] + '...'} [{self.units.get(n) or '?'}]" for n in self.signals]
        shown, size = [], 0
        for name in names:  # the signals, within about 70 characters
            if shown and size + len(name) > 70:
                break
            shown.append(name)
            size += len(name) + 2
        more = f", +{len(names) - len(shown)} more" if len(shown) < len(names) else ""
        return (f"<FlightData {source!r}: {len(self)} samples, Ts {self.ts:g} s, t {self.t[0]:g} to {self.t[-1]:g} s; "
                f"{len(names)} signal{'s' if len(names) != 1 else ''}: {', '.join(shown) or 'none'}{more}>")

    def _repr_html_(self) -> str:
        rows = [[n, self.units.get(n) or "?", float(np.min(x)), float(np.max(x)), float(np.mean(x))]
                for n, x in self.signals.items()]
        return html_table(f"{self.source}: {len(self)} samples, Ts {self.ts:g} s, t {self.t[0]:g} to {self.t[-1]:g} s",
                          ["signal", "unit", "min", "max", "mean"], rows)

    @property
    def ts(self) -> float:
        """Sample time, s."""
        return float(self.t[1] - self.t[0])

    def __len__(self) -> int:
        return self.t.size

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.signals[name]
        except KeyError:
            raise SignalError(f"{self.source}: no signal `{name}`; available: {sorted(self.signals)}") from None

    def resampled(self, ts: float) -> "FlightData":
        """The record on a grid of step ``ts`` from its first time stamp, every signal anti-aliased.

        ``scipy.signal.resample_poly`` with the rational factor ``self.ts / ts`` (denominator at most
        :data:`RESAMPLE_MAX_DENOMINATOR`): its Kaiser-window FIR removes what lies above the new Nyquist
        frequency before decimating, and ``padtype="line"`` continues each end by its trend instead of zeros, so
        the first and last samples carry no start-up transient of the filter.

        Parameters
        ----------
        ts : float
            The new sample time, s (> 0).

        Returns
        -------
        FlightData
            ``metadata["rate_change"]`` records ``from_ts``, ``to_ts``, ``up``, ``down`` and the method; ``self``
            itself where ``ts`` equals its sample time.

        Raises
        ------
        SpecError
            ``ts`` not a finite number > 0, or a ratio to the record's step no fraction up to the denominator
            limit matches within 1e-6.
        """
        from fractions import Fraction

        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not (np.isfinite(ts) and ts > 0):
            raise SpecError(f"`--resample`: got {ts!r}, expected the new sample time, a number > 0 (s)")
        if abs(ts - self.ts) <= 1e-9 * ts:
            return self
        ratio = Fraction(self.ts / ts).limit_denominator(RESAMPLE_MAX_DENOMINATOR)
        if ratio == 0 or abs(float(ratio) - self.ts / ts) > 1e-6 * self.ts / ts:
            raise SpecError(f"`--resample`: {ts!r} s against the record's {self.ts:g} s is no ratio of integers up to "
                            f"{RESAMPLE_MAX_DENOMINATOR}; choose a sample time that divides or multiplies it")
        from scipy.signal import resample_poly

        up, down = ratio.numerator, ratio.denominator
        signals = {n: resample_poly(x, up, down, padtype="line") for n, x in self.signals.items()}
        n = len(next(iter(signals.values())))
        meta = {**self.metadata, "rate_change": {"from_ts": self.ts, "to_ts": float(ts), "up": up, "down": down,
                                               "method": "scipy.signal.resample_poly, padtype line"}}
        return FlightData(self.t[0] + np.arange(n) * ts, signals, dict(self.units), meta, self.source)

    def segment(self, start: float | None = None, stop: float | None = None) -> "FlightData":
        """The samples with ``start <= t <= stop`` (s, same clock as ``t``).

        Parameters
        ----------
        start, stop : float, optional
            Bounds in s (default: the record's first and last time stamps).

        Returns
        -------
        FlightData
            The segment, with ``metadata["segment"] = [start, stop]``.

        Raises
        ------
        SignalError
            The segment holds fewer than 2 samples.
        """
        lo = self.t[0] if start is None else float(start)
        hi = self.t[-1] if stop is None else float(stop)
        keep = (self.t >= lo - 1e-9) & (self.t <= hi + 1e-9)
        if np.count_nonzero(keep) < 2:
            raise SignalError(f"{self.source}: segment [{start}, {stop}] s holds fewer than 2 samples "
                              f"(data span {time_text(self.t[0])} to {time_text(self.t[-1])} s)")
        return FlightData(self.t[keep], {n: x[keep] for n, x in self.signals.items()}, dict(self.units),
                          {**self.metadata, "segment": [lo, hi]}, self.source)

    def missing_samples(self) -> list[tuple[float, float, int]]:
        """Where the original time stamps of this record miss samples, inside its span.

        From ``metadata["sample_gaps"]`` (:meth:`from_samples`: steps longer than
        :data:`SAMPLE_GAP_FACTOR` median steps, which the resampled grid fills by interpolation);
        a gap outside ``t[0]`` to ``t[-1]`` (a segment cut before or after it) is left out.

        Returns
        -------
        list of (float, float, int)
            Per gap, in time order: the last stamp before it and the first after it (s, on the
            clock of ``t``) and the samples of :attr:`ts` missing between them (at least 1).
        """
        ts = self.ts
        tol = 1e-6 * ts
        out = []
        for lo, hi in self.metadata.get("sample_gaps") or []:
            if lo < self.t[-1] - tol and hi > self.t[0] + tol:
                out.append((float(lo), float(hi), max(1, int(round((hi - lo) / ts)) - 1)))
        return out

    def pieces(self) -> list["FlightData"]:
        """The record cut at its gaps (``metadata["gaps"]``): the samples strictly between
        consecutive gaps, each piece a FlightData of its own (one piece when there is none)."""
        gaps = self.metadata.get("gaps") or []
        if not gaps:
            return [self]
        edges = [self.t[0] - 1.0] + [v for g in gaps for v in g] + [self.t[-1] + 1.0]
        out = []
        for i, (lo, hi) in enumerate(zip(edges[::2], edges[1::2])):
            keep = (self.t >= lo) & (self.t <= hi)
            if np.count_nonzero(keep) >= 2:
                meta = {k: v for k, v in self.metadata.items() if k != "gaps"}
                out.append(FlightData(self.t[keep], {n: x[keep] for n, x in self.signals.items()},
                                      dict(self.units), {**meta, "piece": i}, f"{self.source} (piece {i + 1})"))
        return out

    def to_csv(self, path: str) -> None:
        """Write ``time`` and every signal as CSV columns (header row of names), atomically.

        Units go into a comment line before the header: ``# units: time=s, x=m, ...``.

        Parameters
        ----------
        path : str or Path
            The file to write.
        """
        names = list(self.signals)
        units = ", ".join(["time=s"] + [f"{n}={self.units.get(n, '')}" for n in names])
        data = np.column_stack([self.t] + [self.signals[n] for n in names])
        with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
            fh.write(f"# units: {units}\n" + ",".join(csv_field(n) for n in ["time", *names]) + "\n")
            np.savetxt(fh, data, delimiter=",", fmt="%.10g")

    def to_parquet(self, path: str) -> None:
        """Write ``time`` and every signal as Parquet columns, atomically.

        Units are stored in the schema metadata (key ``ilcdob.units``, a JSON object).

        Parameters
        ----------
        path : str or Path
            The file to write.
        """
        import json

        from .extras import require

        pa = require("pyarrow", "logs", f"{path}: writing a Parquet file")
        pq = require("pyarrow.parquet", "logs", f"{path}: writing a Parquet file")

        cols = {"time": self.t, **self.signals}
        table = pa.table(cols).replace_schema_metadata(
            {"ilcdob.units": json.dumps({"time": "s", **self.units})})
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp)


def segments(flights: list[FlightData], length: float, *, min_samples: int = MIN_WINDOW_SAMPLES,
             name: str = "length") -> list[FlightData]:
    """Cut flights into consecutive windows of ``length`` seconds (one fit initial condition each).

    Each flight is cut on its own, from its first sample, into windows of ``round(length / Ts)``
    samples (:meth:`FlightData.segment`, so ``metadata["segment"]`` holds each window's first
    and last time stamp). A last piece of more than half a window (and at least ``min_samples``
    samples) is kept as a window of its own; a shorter one is merged into the window before it,
    which then holds up to one and a half windows. A flight shorter than one window stays
    whole. Every sample lands in exactly one window.

    Parameters
    ----------
    flights : list of FlightData
        The flights, each cut on its own.
    length : float
        Window length, s (finite, > 0).
    min_samples : int
        Fewest samples a window may hold (default :data:`MIN_WINDOW_SAMPLES`).
    name : str
        What ``length`` is called where it was given (e.g. ``"--segment"``), for messages.

    Returns
    -------
    list of FlightData
        The windows of every flight, in order.

    Raises
    ------
    SpecError
        ``length`` is not a finite number > 0, or a window of it holds fewer than
        ``min_samples`` samples at a flight's sample time.
    """
    try:
        seconds = float("nan") if isinstance(length, (bool, np.bool_, str, bytes)) else float(length)
    except (TypeError, ValueError):
        seconds = float("nan")
    if not (np.isfinite(seconds) and seconds > 0):
        raise SpecError(f"`{name}`: got {length!r}, expected a window length in s (a finite number > 0)")
    out = []
    for fd in flights:
        n = int(round(seconds / fd.ts))
        if n < min_samples:
            raise SpecError(f"`{name}`: got {seconds:g} s, a window of {n} samples at the sample time {fd.ts:g} s "
                            f"of {fd.source}; a window must hold at least {min_samples} samples: give at least "
                            f"{min_samples * fd.ts:g} s")
        full, tail = divmod(len(fd), n)
        bounds = [k * n for k in range(max(full, 1))]
        if full >= 1 and tail > 0.5 * n and tail >= min_samples:
            bounds.append(full * n)
        for i, lo in enumerate(bounds):
            hi = bounds[i + 1] - 1 if i + 1 < len(bounds) else len(fd) - 1
            out.append(fd.segment(fd.t[lo], fd.t[hi]))
    return out
