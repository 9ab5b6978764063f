"""Helpers shared by the flight-log loaders.

These checks and conversions are used by several of the format modules (:mod:`.table`,
:mod:`.ulog`, :mod:`.dataflash`):

* selecting signals: :func:`signal_mapping` (signal name -> column, topic field or message
  field), :func:`check_units`, :func:`listing` (what the file holds, for error messages);
* checking the arguments: :func:`source_of`, :func:`check_file`, :func:`check_ts`,
  :func:`check_window`;
* checking the samples: :func:`window_slice` (the samples of the ``start``/``stop`` window),
  :func:`check_stamps`, :func:`check_values`;
* the uniform grid: :func:`from_series` (signals with their own time stamps, ULog and
  DataFlash, interpolated onto one grid) and :func:`checked_segment` (the final
  ``start``/``stop`` crop).

Every error is a :class:`~ilcdob.errors.SignalError` whose message names the file and the
signal.
"""

from __future__ import annotations

import math
import os
from typing import Any, Mapping, Sequence

import numpy as np

from ilcdob.display import time_text
from ilcdob.errors import SignalError
from ilcdob.inputs import MAX_LOG_BYTES, check_input
from ilcdob.signals import FlightData


__all__ = [
    "listing",
    "source_of",
    "check_file",
    "signal_mapping",
    "check_units",
    "check_ts",
    "check_window",
    "window_slice",
    "check_stamps",
    "check_values",
    "checked_segment",
    "from_series",
]

_MAX_LISTED = 60



def listing(names: Sequence[str]) -> str:
    """Names joined by commas for an error message, cut after the first 60.

    Parameters
    ----------
    names : sequence of str
        The names to list (columns, topics, fields, ...).

    Returns
    -------
    str
        ``"a, b, c"``; ``"(none)"`` when empty; beyond 60 names the rest is counted.
    """
    names = list(names)
    if len(names) > _MAX_LISTED:
        return ", ".join(names[:_MAX_LISTED]) + f", ... ({len(names)} in all)"
    return ", ".join(names) if names else "(none)"


def source_of(path: str | os.PathLike) -> str:
    """The file name used in messages and as :attr:`FlightData.source`.

    Parameters
    ----------
    path : str or os.PathLike
        The path given by the caller.

    Returns
    -------
    str
        ``os.fspath(path)``.

    Raises
    ------
    SignalError
        ``path`` is not a str or os.PathLike.
    """
    try:
        return os.fspath(path)
    except TypeError:
        raise SignalError(f"`path`: got {path!r}, expected a file path (str or os.PathLike)") from None


def check_file(source: str) -> None:
    """Check that a file exists, is a regular file of at most :data:`ilcdob.inputs.MAX_LOG_BYTES`
    and is not empty (:func:`ilcdob.inputs.check_input`: a FIFO or a device is refused before it
    is opened, so no reader blocks on it).

    Parameters
    ----------
    source : str
        The file name.

    Raises
    ------
    SignalError
        Missing file, not a regular file, larger than the limit, or 0 bytes.
    """
    if not os.path.exists(source):
        raise SignalError(f"{source}: file not found")
    if check_input(source, "flight log", limit=MAX_LOG_BYTES, error=SignalError) == 0:
        raise SignalError(f"{source}: the file is empty (0 bytes)")


def signal_mapping(names: Mapping[str, str] | Sequence[str], what: str, source: str) -> dict[str, str]:
    """``{signal name: column/field}``; a list of strings maps each to itself.

    Parameters
    ----------
    names : dict of str -> str, or list of str
        Signal name -> column, topic field or message field, as the caller gave it.
    what : str
        Name of the argument in messages (``"columns"`` or ``"fields"``).
    source : str
        The file name, for messages.

    Returns
    -------
    dict of str -> str

    Raises
    ------
    SignalError
        Not a dict or list, empty, a name that is not a non-empty string, the reserved
        name ``"time"``, or a column/field that is not a non-empty string.
    """
    if isinstance(names, Mapping):
        out = dict(names)
    elif isinstance(names, (list, tuple)):
        out = {n: n for n in names}
    else:
        raise SignalError(f"{source}: `{what}`: got {type(names).__name__} {names!r}, expected a dict "
                          f"{{signal name: {what[:-1]}}} or a list of {what}")
    if not out:
        raise SignalError(f"{source}: `{what}`: empty; give at least one {{signal name: {what[:-1]}}}")
    for name, col in out.items():
        if not isinstance(name, str) or not name:
            raise SignalError(f"{source}: `{what}`: signal name {name!r} is not a non-empty string")
        if name == "time":
            raise SignalError(f"{source}: `{what}`: the signal name 'time' is reserved for the time grid; "
                              f"choose another name for {col!r}")
        if not isinstance(col, str) or not col:
            raise SignalError(f"{source}: `{what}`: signal `{name}`: got {col!r}, expected a non-empty string")
    return out


def check_units(units: Mapping[str, str] | None, names: Sequence[str], source: str,
                 allow_time: bool = False) -> dict[str, str]:
    """Check the ``units`` argument of a loader.

    Parameters
    ----------
    units : dict of str -> str, optional
        Signal name -> unit string, as the caller gave it.
    names : sequence of str
        The output signal names.
    source : str
        The file name, for messages.
    allow_time : bool, optional
        Whether ``"time"`` is also a valid key (tables: the unit of the time column).

    Returns
    -------
    dict of str -> str
        A copy of ``units``; empty when it is None.

    Raises
    ------
    SignalError
        Not a dict, an unknown signal name, or a unit that is not a string.
    """
    if units is None:
        return {}
    if not isinstance(units, Mapping):
        raise SignalError(f"{source}: `units`: got {type(units).__name__}, expected a dict {{signal name: unit}}")
    valid = list(names) + (["time"] if allow_time else [])
    for k, v in units.items():
        if k not in valid:
            raise SignalError(f"{source}: `units`: unknown signal {k!r}; valid: {listing(valid)}")
        if not isinstance(v, str):
            raise SignalError(f"{source}: `units`: signal `{k}`: got {v!r}, expected a unit string such as 'm'")
    return dict(units)


def check_ts(ts: float | None, source: str) -> float | None:
    """Check the ``ts`` argument (sample time of the result, s).

    Parameters
    ----------
    ts : float, optional
        The sample time as the caller gave it.
    source : str
        The file name, for messages.

    Returns
    -------
    float or None
        ``ts`` as float, or None.

    Raises
    ------
    SignalError
        Not a finite number > 0.
    """
    if ts is None:
        return None
    try:
        ts_f = float(ts)
    except (TypeError, ValueError):
        raise SignalError(f"{source}: `ts`: got {ts!r}, expected a sample time > 0 (s)") from None
    if not (math.isfinite(ts_f) and ts_f > 0):
        raise SignalError(f"{source}: `ts`: got {ts!r}, expected a sample time > 0 (s)")
    return ts_f


def check_window(start: float | None, stop: float | None, source: str) -> tuple[float | None, float | None]:
    """Check the ``start`` and ``stop`` arguments (s, on the log's clock).

    Parameters
    ----------
    start, stop : float, optional
        The window as the caller gave it.
    source : str
        The file name, for messages.

    Returns
    -------
    tuple of (float or None, float or None)
        ``(start, stop)`` as floats.

    Raises
    ------
    SignalError
        A value that is not a finite number, or ``stop <= start``.
    """
    out = []
    for name, v in (("start", start), ("stop", stop)):
        if v is None:
            out.append(None)
            continue
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise SignalError(f"{source}: `{name}`: got {v!r}, expected a time in s (log clock) or None") from None
        if not math.isfinite(f):
            raise SignalError(f"{source}: `{name}`: got {v!r}, expected a finite time in s (log clock) or None")
        out.append(f)
    if out[0] is not None and out[1] is not None and out[1] <= out[0]:
        raise SignalError(f"{source}: `stop` = {out[1]!r} s is not after `start` = {out[0]!r} s; "
                          f"expected start < stop")
    return out[0], out[1]


def window_slice(t: np.ndarray, start: float | None, stop: float | None, source: str,
                  what: str) -> slice:
    """Contiguous slice of the samples in ``[start, stop]`` plus one on each side.

    Parameters
    ----------
    t : numpy.ndarray
        Time stamps, s.
    start, stop : float or None
        The window, s; None leaves that side open.
    source : str
        The file name, for messages.
    what : str
        What the stamps belong to, for messages (e.g. ``"signal `y` (column `x`)"``).

    Returns
    -------
    slice
        The whole array when both ``start`` and ``stop`` are None.

    Raises
    ------
    SignalError
        No sample in the window (empty selection).
    """
    if start is None and stop is None:
        return slice(0, t.size)
    lo = -np.inf if start is None else start
    hi = np.inf if stop is None else stop
    idx = np.flatnonzero((t >= lo - 1e-9) & (t <= hi + 1e-9))
    if idx.size == 0:
        span = (f"{time_text(np.nanmin(t))} to {time_text(np.nanmax(t))} s" if t.size and np.any(np.isfinite(t))
                else "empty")
        raise SignalError(f"{source}: {what}: empty selection: no samples in [start, stop] = "
                          f"[{start}, {stop}] s (data span {span})")
    return slice(max(int(idx[0]) - 1, 0), min(int(idx[-1]) + 2, t.size))


def check_stamps(t: np.ndarray, source: str, what: str, rows: np.ndarray | None = None) -> None:
    """Finite, strictly increasing time stamps (at least 2); messages name line or sample.

    Parameters
    ----------
    t : numpy.ndarray
        Time stamps, s.
    source : str
        The file name, for messages.
    what : str
        What the stamps belong to, for messages.
    rows : numpy.ndarray, optional
        Line number of each stamp in the file (text tables); messages then name the line
        instead of the sample index.

    Raises
    ------
    SignalError
        Fewer than 2 stamps, a non-finite stamp, or stamps that are duplicated or decreasing.
    """
    if t.size < 2:
        raise SignalError(f"{source}: {what}: {t.size} sample(s); expected at least 2")

    def at(k: int) -> str:
        return f"line {int(rows[k])}" if rows is not None else f"sample {k}"

    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        k = int(bad[0])
        raise SignalError(f"{source}: {what}: non-finite time stamp {float(t[k])!r} at {at(k)}")
    dt = np.diff(t)
    same, back = np.flatnonzero(dt == 0), np.flatnonzero(dt < 0)
    if same.size:
        k = int(same[0])
        also = f", and {back.size} step(s) back" if back.size else ""
        raise SignalError(f"{source}: {what}: duplicated time stamp {float(t[k]):.9g} s at {at(k)} and "
                          f"{at(k + 1)} ({same.size} repeated stamp(s) in all{also}); expected strictly "
                          "increasing time stamps, one per sample: choose start/stop to exclude them")
    if back.size:
        k = int(back[0])
        raise SignalError(f"{source}: {what}: time stamps not increasing at {at(k + 1)} "
                          f"({float(t[k]):.9g} -> {float(t[k + 1]):.9g} s), {back.size} step(s) back in all; "
                          "expected strictly increasing, one stamp per sample: choose start/stop to exclude them")


def check_values(x: np.ndarray, t: np.ndarray, source: str, what: str,
                  rows: np.ndarray | None = None) -> None:
    """Check that every value of a signal is finite.

    Parameters
    ----------
    x : numpy.ndarray
        The values.
    t : numpy.ndarray
        Their time stamps, s.
    source : str
        The file name, for messages.
    what : str
        The signal, for messages.
    rows : numpy.ndarray, optional
        Line number of each value in the file (text tables).

    Raises
    ------
    SignalError
        A NaN or infinite value (the message gives the first and how many there are).
    """
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        k = int(bad[0])
        where = f"line {int(rows[k])}, " if rows is not None else ""
        raise SignalError(f"{source}: {what}: non-finite value {float(x[k])!r} at {where}t = {t[k]:.9g} s "
                          f"(sample {k}; {bad.size} non-finite in all); expected finite numbers -- "
                          f"choose start/stop to exclude them")


def checked_segment(fd: FlightData, start: float | None, stop: float | None) -> FlightData:
    """:meth:`FlightData.segment`, with an error naming the file when the window misses the data.

    Parameters
    ----------
    fd : FlightData
        The loaded flight.
    start, stop : float or None
        The window, s; None leaves that side open.

    Returns
    -------
    FlightData
        ``fd`` itself when both ``start`` and ``stop`` are None.

    Raises
    ------
    SignalError
        The window does not overlap the data span.
    """
    if start is None and stop is None:
        return fd
    lo = fd.t[0] if start is None else max(start, fd.t[0])
    hi = fd.t[-1] if stop is None else min(stop, fd.t[-1])
    if hi < lo:
        raise SignalError(f"{fd.source}: empty selection: [start, stop] = [{start}, {stop}] s does not "
                          f"overlap the data span {time_text(fd.t[0])} to {time_text(fd.t[-1])} s")
    return fd.segment(start, stop)



def from_series(series: dict[str, tuple[np.ndarray, np.ndarray]], what: dict[str, str], units: dict[str, str],
                 meta: dict[str, Any], ts: float | None, start: float | None, stop: float | None,
                 source: str) -> FlightData:
    """Checks and common grid for signals with their own time stamps (ULog, DataFlash).

    Each signal is cut to the ``start``/``stop`` window (its samples at the window edges
    replaced by the values interpolated there), checked, and all are interpolated onto
    one uniform grid over the time they overlap (:meth:`FlightData.from_samples`).

    Parameters
    ----------
    series : dict of str -> (numpy.ndarray, numpy.ndarray)
        Signal name -> (time stamps in s, values).
    what : dict of str -> str
        Signal name -> description for messages (signal, topic or message, field).
    units : dict of str -> str
        Unit of each signal.
    meta : dict
        Metadata of the result.
    ts : float or None
        Sample time of the grid, s; None: the finest median step of the signals.
    start, stop : float or None
        The window, s on the log's clock.
    source : str
        The file name, for messages and :attr:`FlightData.source`.

    Returns
    -------
    FlightData

    Raises
    ------
    SignalError
        An empty selection, bad time stamps or values, or signals that do not overlap in time.
    """
    cropped = {}
    for name, (t, x) in series.items():
        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        sl = window_slice(t, start, stop, source, what[name])
        t, x = t[sl], x[sl]
        check_stamps(t, source, what[name])
        check_values(x, t, source, what[name])
        # anchor the grid at start/stop: replace the margin samples by the interpolated
        # values at start and stop (exact for the linear interpolation used on the grid)
        if start is not None and t[0] < start - 1e-12 < t[-1]:
            keep = t > start + 1e-12
            t, x = np.r_[start, t[keep]], np.r_[np.interp(start, t, x), x[keep]]
        if stop is not None and t[0] < stop + 1e-12 < t[-1]:
            keep = t < stop - 1e-12
            t, x = np.r_[t[keep], stop], np.r_[x[keep], np.interp(stop, t, x)]
        cropped[name] = (t, x)
    t0 = max(t[0] for t, _ in cropped.values())
    t1 = min(t[-1] for t, _ in cropped.values())
    if t1 <= t0:
        spans = "; ".join(f"{what[n]}: {t[0]:.6g} to {t[-1]:.6g} s" for n, (t, _) in cropped.items())
        raise SignalError(f"{source}: the selected signals do not overlap in time ({spans})")
    fd = FlightData.from_samples(cropped, ts=ts, units=units, metadata=meta, source=source)
    return checked_segment(fd, start, stop)
