"""Loaders of flight logs into :class:`~ilcdob.signals.FlightData`.

One function per source, each returning a :class:`FlightData` on a uniform time grid:

* :func:`load_csv` -- comma-separated text with a header row (our own
  :meth:`FlightData.to_csv` output, or any logger's CSV);
* :func:`load_parquet` -- Parquet tables (pyarrow);
* :func:`load_ulog` -- PX4 ULog ``.ulg`` files (pyulog);
* :func:`load_dataflash` -- ArduPilot DataFlash logs, binary ``.bin`` or text ``.log``
  (pymavlink's DFReader);
* :func:`load_flight` -- dispatch on the file suffix.

Conventions
-----------
Time is in s on the log's own clock (seconds since boot for ULog and DataFlash, the time
column as written for CSV/Parquet); it is **not** shifted to start at zero, so ``start`` and
``stop`` (s) are read on that same clock. Signals from topics or message types logged at
different rates are linearly interpolated onto one grid whose step is the finest median
step among them (or ``ts`` when given) and which spans the time all of them overlap
(:meth:`FlightData.from_samples`). Table sources (CSV, Parquet) keep their own samples when
the time column is uniform to within :data:`SNAP_RTOL` of a step (the stamps are then
replaced by the exact grid ``t0 + k ts``, which absorbs the rounding of a text writer) and
are resampled otherwise. A table clock at Unix-epoch magnitude (>= :data:`EPOCH_SHIFT_S`,
or an Arrow timestamp column) is shifted to start at the file's first stamp, kept in
``metadata["time_origin_s"]`` (float64 cannot hold a uniform grid at 1e9 s to the precision
:class:`FlightData` checks); ``start``/``stop`` are still given on the file's clock.

With ``start``/``stop`` only the samples of the window (plus one on each side, so that the
interpolation at the edges is exact) are checked and converted: a log whose estimator
wrote NaN before it converged can be loaded from the clean part. For logs (ULog,
DataFlash) the common grid then starts exactly at ``start`` when every selected signal has
data there (``t = start + k ts``).

Every error is a :class:`~ilcdob.errors.SignalError` whose message names the file, the
signal (and the column, topic or field it came from), the value received and what is valid.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import re
import warnings
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from ilcdob.errors import SignalError
from ilcdob.signals import FlightData


__all__ = [
    "load_csv",
    "load_parquet",
    "load_ulog",
    "load_dataflash",
    "load_flight",
    "SUFFIXES",
    "SNAP_RTOL",
    "EPOCH_SHIFT_S",
]

#: A table's time column counts as uniform when every stamp lies within this fraction of a
#: sample step of the straight line ``t0 + k ts``; it is then snapped onto that line.
SNAP_RTOL = 1e-3

#: File suffix (lower case) -> loader name, used by :func:`load_flight`.
SUFFIXES: dict[str, str] = {
    ".csv": "load_csv",
    ".parquet": "load_parquet",
    ".pq": "load_parquet",
    ".ulg": "load_ulog",
    ".bin": "load_dataflash",
    ".log": "load_dataflash",
}

#: A table time column whose values reach this magnitude (s; a Unix-epoch clock) is shifted
#: to start at 0, the origin kept in ``metadata["time_origin_s"]``: float64 cannot hold a
#: uniform grid at 1e9 s to the precision :class:`FlightData` checks.
EPOCH_SHIFT_S = 1e7

#: Time units accepted for a table's time column (factor to s).
_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "ns": 1e-9}

#: Units of common PX4 uORB fields (index suffixes such as ``[0]`` are stripped first);
#: ULog files carry no units of their own.
_PX4_UNITS: dict[str, dict[str, str]] = {
    "vehicle_local_position": {
        "x": "m", "y": "m", "z": "m", "vx": "m/s", "vy": "m/s", "vz": "m/s", "z_deriv": "m/s",
        "ax": "m/s^2", "ay": "m/s^2", "az": "m/s^2", "heading": "rad", "dist_bottom": "m",
    },
    "vehicle_local_position_setpoint": {
        "x": "m", "y": "m", "z": "m", "vx": "m/s", "vy": "m/s", "vz": "m/s",
        "acceleration": "m/s^2", "jerk": "m/s^3", "thrust": "", "yaw": "rad", "yawspeed": "rad/s",
    },
    "trajectory_setpoint": {
        "position": "m", "velocity": "m/s", "acceleration": "m/s^2", "jerk": "m/s^3",
        "yaw": "rad", "yawspeed": "rad/s",
    },
    "vehicle_acceleration": {"xyz": "m/s^2"},
    "vehicle_angular_velocity": {"xyz": "rad/s"},
    "vehicle_angular_acceleration": {"xyz": "rad/s^2"},
    "sensor_combined": {"gyro_rad": "rad/s", "accelerometer_m_s2": "m/s^2"},
    "vehicle_attitude": {"q": ""},
    "vehicle_attitude_setpoint": {"roll_body": "rad", "pitch_body": "rad", "yaw_body": "rad",
                                  "q_d": "", "thrust_body": ""},
}

_MAX_LISTED = 60


# --------------------------------------------------------------------------------------
# shared helpers
# --------------------------------------------------------------------------------------

def _listing(names: Sequence[str]) -> str:
    names = list(names)
    if len(names) > _MAX_LISTED:
        return ", ".join(names[:_MAX_LISTED]) + f", ... ({len(names)} in all)"
    return ", ".join(names) if names else "(none)"


def _source_of(path: str | os.PathLike) -> str:
    try:
        return os.fspath(path)
    except TypeError:
        raise SignalError(f"`path`: got {path!r}, expected a file path (str or os.PathLike)") from None


def _check_file(source: str) -> None:
    if not os.path.exists(source):
        raise SignalError(f"{source}: file not found")
    if not os.path.isfile(source):
        raise SignalError(f"{source}: not a regular file")
    if os.path.getsize(source) == 0:
        raise SignalError(f"{source}: the file is empty (0 bytes)")


def _mapping(names: Mapping[str, str] | Sequence[str], what: str, source: str) -> dict[str, str]:
    """``{signal name: column/field}``; a list of strings maps each to itself."""
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


def _check_units(units: Mapping[str, str] | None, names: Sequence[str], source: str,
                 allow_time: bool = False) -> dict[str, str]:
    if units is None:
        return {}
    if not isinstance(units, Mapping):
        raise SignalError(f"{source}: `units`: got {type(units).__name__}, expected a dict {{signal name: unit}}")
    valid = list(names) + (["time"] if allow_time else [])
    for k, v in units.items():
        if k not in valid:
            raise SignalError(f"{source}: `units`: unknown signal {k!r}; valid: {_listing(valid)}")
        if not isinstance(v, str):
            raise SignalError(f"{source}: `units`: signal `{k}`: got {v!r}, expected a unit string such as 'm'")
    return dict(units)


def _check_ts(ts: float | None, source: str) -> float | None:
    if ts is None:
        return None
    try:
        ts_f = float(ts)
    except (TypeError, ValueError):
        raise SignalError(f"{source}: `ts`: got {ts!r}, expected a sample time > 0 (s)") from None
    if not (math.isfinite(ts_f) and ts_f > 0):
        raise SignalError(f"{source}: `ts`: got {ts!r}, expected a sample time > 0 (s)")
    return ts_f


def _check_window(start: float | None, stop: float | None, source: str) -> tuple[float | None, float | None]:
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


def _window_slice(t: np.ndarray, start: float | None, stop: float | None, source: str,
                  what: str) -> slice:
    """Contiguous slice of the samples in ``[start, stop]`` plus one on each side."""
    if start is None and stop is None:
        return slice(0, t.size)
    lo = -np.inf if start is None else start
    hi = np.inf if stop is None else stop
    idx = np.flatnonzero((t >= lo - 1e-9) & (t <= hi + 1e-9))
    if idx.size == 0:
        span = f"{np.nanmin(t):.6g} to {np.nanmax(t):.6g} s" if t.size and np.any(np.isfinite(t)) else "empty"
        raise SignalError(f"{source}: {what}: empty selection: no samples in [start, stop] = "
                          f"[{start}, {stop}] s (data span {span})")
    return slice(max(int(idx[0]) - 1, 0), min(int(idx[-1]) + 2, t.size))


def _check_stamps(t: np.ndarray, source: str, what: str, rows: np.ndarray | None = None) -> None:
    """Finite, strictly increasing time stamps (at least 2); messages name line or sample."""
    if t.size < 2:
        raise SignalError(f"{source}: {what}: {t.size} sample(s); expected at least 2")

    def at(k: int) -> str:
        return f"line {int(rows[k])}" if rows is not None else f"sample {k}"

    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        k = int(bad[0])
        raise SignalError(f"{source}: {what}: non-finite time stamp {float(t[k])!r} at {at(k)}")
    dt = np.diff(t)
    if np.any(dt == 0):
        k = int(np.flatnonzero(dt == 0)[0])
        raise SignalError(f"{source}: {what}: duplicated time stamp {float(t[k]):.9g} s at {at(k)} and "
                          f"{at(k + 1)}; expected strictly increasing time stamps")
    if np.any(dt < 0):
        k = int(np.flatnonzero(dt < 0)[0])
        raise SignalError(f"{source}: {what}: time stamps not increasing at {at(k + 1)} "
                          f"({float(t[k]):.9g} -> {float(t[k + 1]):.9g} s); expected strictly increasing")


def _check_values(x: np.ndarray, t: np.ndarray, source: str, what: str,
                  rows: np.ndarray | None = None) -> None:
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        k = int(bad[0])
        where = f"line {int(rows[k])}, " if rows is not None else ""
        raise SignalError(f"{source}: {what}: non-finite value {float(x[k])!r} at {where}t = {t[k]:.9g} s "
                          f"(sample {k}; {bad.size} non-finite in all); expected finite numbers -- "
                          f"choose start/stop to exclude them")


def _segment(fd: FlightData, start: float | None, stop: float | None) -> FlightData:
    if start is None and stop is None:
        return fd
    lo = fd.t[0] if start is None else max(start, fd.t[0])
    hi = fd.t[-1] if stop is None else min(stop, fd.t[-1])
    if hi < lo:
        raise SignalError(f"{fd.source}: empty selection: [start, stop] = [{start}, {stop}] s does not "
                          f"overlap the data span {fd.t[0]:.6g} to {fd.t[-1]:.6g} s")
    return fd.segment(start, stop)


def _snap_window(t: np.ndarray, start: float | None, stop: float | None,
                 origin: float) -> tuple[float | None, float | None]:
    """``start``/``stop`` minus ``origin``, moved onto a time stamp within the float
    resolution of the original clock (a few ulp of ``origin``)."""
    tol = 4 * float(np.spacing(abs(origin)))
    out = []
    for v in (start, stop):
        if v is None:
            out.append(None)
            continue
        v = v - origin
        k = int(np.argmin(np.abs(t - v)))
        out.append(float(t[k]) if abs(t[k] - v) <= tol else v)
    return out[0], out[1]


def _from_table(t: np.ndarray, cols: dict[str, np.ndarray], what: dict[str, str], units: dict[str, str],
                meta: dict[str, Any], ts: float | None, start: float | None, stop: float | None,
                source: str, rows: np.ndarray | None = None, origin: float = 0.0) -> FlightData:
    """Checks and grid for the common time column of a table (CSV, Parquet).

    The file's clock is ``t + origin``; ``start``/``stop`` are on the file's clock.
    """
    if not origin and t.size and np.isfinite(t[0]) and abs(t[0]) >= EPOCH_SHIFT_S:
        origin = float(t[0])
        t = t - origin
    if origin:
        start, stop = _snap_window(t, start, stop, origin)
        meta["time_origin_s"] = origin
    tcol = f"time column `{meta.get('time_column', 'time')}`"
    sl = _window_slice(t, start, stop, source, tcol)
    t = t[sl]
    rows = rows[sl] if rows is not None else None
    _check_stamps(t, source, tcol, rows)
    cols = {n: x[sl] for n, x in cols.items()}
    for n, x in cols.items():
        _check_values(x, t, source, what[n], rows)
    n = t.size
    step = (t[-1] - t[0]) / (n - 1)
    dev = float(np.max(np.abs(t - (t[0] + np.arange(n) * step))))
    uniform = dev <= SNAP_RTOL * step
    if uniform and (ts is None or abs(ts - step) <= 1e-9 * step):
        grid = t[0] + np.arange(n) * step
        meta.update(resampled=False, time_snap_max_s=dev)
        fd = FlightData(grid, cols, units, meta, source)
    else:
        meta.update(resampled=True)
        fd = FlightData.from_samples({k: (t, x) for k, x in cols.items()}, ts=ts, units=units,
                                     metadata=meta, source=source)
    return _segment(fd, start, stop)


def _from_series(series: dict[str, tuple[np.ndarray, np.ndarray]], what: dict[str, str], units: dict[str, str],
                 meta: dict[str, Any], ts: float | None, start: float | None, stop: float | None,
                 source: str) -> FlightData:
    """Checks and common grid for signals with their own time stamps (ULog, DataFlash)."""
    cropped = {}
    for name, (t, x) in series.items():
        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        sl = _window_slice(t, start, stop, source, what[name])
        t, x = t[sl], x[sl]
        _check_stamps(t, source, what[name])
        _check_values(x, t, source, what[name])
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
    return _segment(fd, start, stop)


# --------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------

_UNITS_LINE = re.compile(r"^\s*#\s*units\s*:\s*(.*)$", re.IGNORECASE)


def _parse_units_line(text: str) -> dict[str, str]:
    units = {}
    for item in text.split(","):
        if "=" in item:
            k, v = item.split("=", 1)
            units[k.strip()] = v.strip()
    return units


def _time_scale(unit: str, source: str, column: str) -> float:
    u = unit.strip()
    if u == "":
        return 1.0
    if u not in _TIME_UNITS:
        raise SignalError(f"{source}: column `{column}`: time unit {unit!r} not supported; "
                          f"valid: {', '.join(_TIME_UNITS)}")
    return _TIME_UNITS[u]


#: Median time step (s) above which a time column whose unit is not stated (and so is read as
#: seconds) draws a warning: flight logs sample at 1 Hz or faster, and a step of 10 read as
#: 10 s is usually 10 ms.
UNSTATED_UNIT_STEP_S = 0.5


def _warn_unstated_unit(t: np.ndarray, stated: bool, source: str, column: str) -> None:
    """Warn when an unstated time unit read as s gives a step that looks like milliseconds."""
    if stated or t.size < 3:
        return
    step = float(np.median(np.diff(t)))
    if step >= UNSTATED_UNIT_STEP_S:
        warnings.warn(f"{source}: time column `{column}`: no unit stated, read as s: median step {step:g} s "
                      f"({1.0 / step:.3g} Hz); if the stamps are milliseconds, state it (units={{'time': 'ms'}}, "
                      "a '# units: time=ms' line, or identify --time-unit ms)", UserWarning, stacklevel=3)


def _tabular_arguments(path, columns, time, units, ts, start, stop):
    """Check the arguments shared by the CSV and Parquet loaders."""
    source = _source_of(path)
    cols = _mapping(columns, "columns", source)
    if not isinstance(time, str) or not time:
        raise SignalError(f"{source}: `time`: got {time!r}, expected the name of the time column")
    units_arg = _check_units(units, list(cols), source, allow_time=True)
    ts = _check_ts(ts, source)
    start, stop = _check_window(start, stop, source)
    _check_file(source)
    return source, cols, units_arg, ts, start, stop


def load_csv(path: str | os.PathLike, columns: Mapping[str, str] | Sequence[str], time: str = "time",
             units: Mapping[str, str] | None = None, ts: float | None = None,
             start: float | None = None, stop: float | None = None) -> FlightData:
    """Load signals from a CSV file with a header row.

    Lines whose first non-blank character is ``#`` are comments; a comment
    ``# units: time=s, x=m, ...`` (what :meth:`FlightData.to_csv` writes) gives the unit of
    each column. Blank lines are skipped.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file.
    columns : dict of str -> str, or list of str
        Output signal name -> CSV column name, e.g. ``{"u": "acc_cmd", "y": "x"}``; a list
        keeps the column names.
    time : str
        Name of the time column. Its unit is taken from ``units["time"]``, else from the
        units comment, else s; ``ms``, ``us`` and ``ns`` are converted to s.
    units : dict of str -> str, optional
        Unit of each output signal (and of ``"time"``); overrides the units comment.
    ts : float, optional
        Sample time of the result, s; default: the file's own step (resampled by linear
        interpolation only when the time column is not uniform or ``ts`` differs).
    start, stop : float, optional
        Keep ``start <= t <= stop`` (s, on the file's clock).

    Returns
    -------
    FlightData
        ``source`` is the file name; ``metadata`` holds ``format``, ``columns``,
        ``time_column`` and ``resampled``.

    Raises
    ------
    SignalError
        Missing file or column (the message lists the columns present), a non-numeric or
        empty cell, a row of the wrong length, non-finite values, time stamps that are not
        strictly increasing, or an empty selection.
    """
    source, cols, units_arg, ts, start, stop = _tabular_arguments(path, columns, time, units, ts, start, stop)

    try:
        with open(source, encoding="utf-8", newline="") as fh:
            lines = fh.read().splitlines()
    except UnicodeDecodeError as exc:
        raise SignalError(f"{source}: not a UTF-8 text file ({exc}); expected CSV text") from None
    except OSError as exc:
        raise SignalError(f"{source}: cannot read the file ({exc})") from None

    file_units: dict[str, str] = {}
    body: list[str] = []
    line_no: list[int] = []
    for i, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            m = _UNITS_LINE.match(stripped)
            if m:
                file_units.update(_parse_units_line(m.group(1)))
            continue
        body.append(line)
        line_no.append(i)
    if not body:
        raise SignalError(f"{source}: no header row (only comments or blank lines); expected a row of "
                          f"column names such as `time,x`")
    try:
        rows = list(csv.reader(body))
    except csv.Error as exc:
        raise SignalError(f"{source}: malformed CSV ({exc})") from None
    if len(rows) != len(body):  # a quoted field spanning lines: line numbers become approximate
        line_no = list(range(1, len(rows) + 1))
    header = [h.strip() for h in rows[0]]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise SignalError(f"{source}: line {line_no[0]}: duplicated column name(s) {dup} in the header")
    wanted = [time] + list(cols.values())
    missing = [c for c in wanted if c not in header]
    if missing:
        which = "time column" if missing[0] == time else "column"
        sig = next((n for n, c in cols.items() if c == missing[0]), "time")
        raise SignalError(f"{source}: signal `{sig}`: {which} {missing[0]!r} not found; "
                          f"columns present: {_listing(header)}")
    data_rows = rows[1:]
    data_lines = np.asarray(line_no[1:], dtype=int)
    if len(data_rows) < 2:
        raise SignalError(f"{source}: {len(data_rows)} data row(s) after the header; expected at least 2")
    index = {c: header.index(c) for c in wanted}
    out = {c: np.empty(len(data_rows)) for c in wanted}
    width = len(header)
    for r, row in enumerate(data_rows):
        if len(row) != width:
            raise SignalError(f"{source}: line {data_lines[r]}: {len(row)} fields, expected {width} "
                              f"(as in the header)")
        for c, j in index.items():
            cell = row[j].strip()
            try:
                out[c][r] = float(cell)
            except ValueError:
                what = "empty value" if cell == "" else f"non-numeric value {cell!r}"
                raise SignalError(f"{source}: line {data_lines[r]}: column `{c}`: {what}; expected a "
                                  f"number") from None

    tunit = units_arg.get("time", file_units.get(time, "s"))
    scale = _time_scale(tunit, source, time)
    t = out[time] * scale
    _warn_unstated_unit(t, "time" in units_arg or time in file_units, source, time)
    origin = 0.0
    if np.isfinite(t[0]) and abs(t[0]) >= EPOCH_SHIFT_S:
        # subtract the first stamp in decimal arithmetic: exact differences of the text
        j = index[time]
        try:
            first = Decimal(data_rows[0][j].strip())
            t = np.array([float(Decimal(row[j].strip()) - first) for row in data_rows]) * scale
            origin = float(first) * scale
        except (InvalidOperation, ValueError):
            pass
    sig_units = {n: units_arg.get(n, file_units.get(c, "")) for n, c in cols.items()}
    what = {n: f"signal `{n}` (column `{c}`)" for n, c in cols.items()}
    meta = {"format": "csv", "columns": dict(cols), "time_column": time}
    return _from_table(t, {n: out[c] for n, c in cols.items()}, what, sig_units, meta, ts, start, stop,
                       source, rows=data_lines, origin=origin)


# --------------------------------------------------------------------------------------
# Parquet
# --------------------------------------------------------------------------------------

def _arrow_to_float(col: Any, source: str, column: str, is_time: bool) -> tuple[np.ndarray, float]:
    """Values as float and an origin to add (non-zero only for timestamp/duration columns,
    converted relative to their first value in integer arithmetic)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if col.null_count:
        first = int(np.flatnonzero(np.asarray(pc.is_null(col).to_numpy(zero_copy_only=False)))[0])
        raise SignalError(f"{source}: column `{column}`: {col.null_count} missing (null) value(s), first at "
                          f"row {first}; expected numbers")
    typ = col.type
    if is_time and (pa.types.is_timestamp(typ) or pa.types.is_duration(typ)):
        scale = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[typ.unit]
        ints = np.asarray(col.cast(pa.int64()).to_numpy(zero_copy_only=False), dtype=np.int64)
        if ints.size == 0:
            return ints.astype(float), 0.0
        return (ints - ints[0]).astype(float) * scale, float(ints[0]) * scale
    if not (pa.types.is_integer(typ) or pa.types.is_floating(typ) or pa.types.is_boolean(typ)
            or pa.types.is_decimal(typ)):
        raise SignalError(f"{source}: column `{column}`: type {typ}, expected numbers"
                          + (" or a timestamp" if is_time else ""))
    return np.asarray(col.to_numpy(zero_copy_only=False), dtype=float), 0.0


def load_parquet(path: str | os.PathLike, columns: Mapping[str, str] | Sequence[str], time: str = "time",
                 units: Mapping[str, str] | None = None, ts: float | None = None,
                 start: float | None = None, stop: float | None = None) -> FlightData:
    """Load signals from a Parquet file (pyarrow).

    Units come from the JSON object stored under the schema metadata key ``ilcdob.units``
    (what :meth:`FlightData.to_parquet` writes), overridden by ``units``. A time column of
    Arrow type timestamp or duration is converted to s (a timestamp: s since the Unix
    epoch).

    Parameters
    ----------
    path, columns, time, units, ts, start, stop
        As in :func:`load_csv`.

    Returns
    -------
    FlightData

    Raises
    ------
    SignalError
        Missing file or column (the message lists the columns present), a file pyarrow
        cannot read, null or non-numeric values, non-finite values, time stamps that are not
        strictly increasing, or an empty selection.
    """
    import pyarrow.parquet as pq

    source, cols, units_arg, ts, start, stop = _tabular_arguments(path, columns, time, units, ts, start, stop)
    try:
        schema = pq.read_schema(source)
    except Exception as exc:  # pyarrow raises ArrowInvalid, OSError, ... for a bad file
        raise SignalError(f"{source}: cannot read as Parquet ({type(exc).__name__}: {exc})") from None
    names = list(schema.names)
    wanted = [time] + [c for c in cols.values() if c != time]
    missing = [c for c in wanted if c not in names]
    if missing:
        which = "time column" if missing[0] == time else "column"
        sig = next((n for n, c in cols.items() if c == missing[0]), "time")
        raise SignalError(f"{source}: signal `{sig}`: {which} {missing[0]!r} not found; "
                          f"columns present: {_listing(names)}")
    file_units: dict[str, str] = {}
    raw = (schema.metadata or {}).get(b"ilcdob.units")
    if raw is not None:
        try:
            parsed = json.loads(raw.decode("utf-8"))
            if isinstance(parsed, dict):
                file_units = {str(k): str(v) for k, v in parsed.items()}
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise SignalError(f"{source}: schema metadata `ilcdob.units` is not a JSON object ({exc})") from None
    try:
        table = pq.read_table(source, columns=list(dict.fromkeys(wanted)))
    except Exception as exc:
        raise SignalError(f"{source}: cannot read the Parquet data ({type(exc).__name__}: {exc})") from None
    data = {c: _arrow_to_float(table.column(c), source, c, c == time) for c in dict.fromkeys(wanted)}
    tunit = units_arg.get("time", file_units.get(time, "s"))
    t, origin = data[time]
    if not origin:
        t = t * _time_scale(tunit, source, time)
    _warn_unstated_unit(t, "time" in units_arg or time in file_units, source, time)
    sig_units = {n: units_arg.get(n, file_units.get(c, "")) for n, c in cols.items()}
    what = {n: f"signal `{n}` (column `{c}`)" for n, c in cols.items()}
    meta = {"format": "parquet", "columns": dict(cols), "time_column": time}
    return _from_table(t, {n: data[c][0] for n, c in cols.items()}, what, sig_units, meta, ts, start, stop,
                       source, origin=origin)


# --------------------------------------------------------------------------------------
# PX4 ULog
# --------------------------------------------------------------------------------------

_ULOG_SPEC = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?::(\d+))?\.(\S+)$")


def _parse_ulog_spec(spec: str, name: str, source: str) -> tuple[str, int, str]:
    m = _ULOG_SPEC.match(spec.strip())
    if not m:
        raise SignalError(f"{source}: signal `{name}`: field {spec!r} not of the form 'topic.field' or "
                          f"'topic:instance.field' (e.g. 'vehicle_local_position.x')")
    return m.group(1), int(m.group(2) or 0), m.group(3)


def _ulog_topics(source: str) -> list[str]:
    """Every topic (with instance when > 0) that has data in the file; for error messages."""
    from pyulog import ULog

    try:
        ulog = ULog(source)
    except Exception:
        return []
    return sorted({d.name if d.multi_id == 0 else f"{d.name}:{d.multi_id}" for d in ulog.data_list})


def _px4_unit(topic: str, field: str) -> str:
    base = re.sub(r"\[\d+\]$", "", field)
    return _PX4_UNITS.get(topic, {}).get(base, "")


def load_ulog(path: str | os.PathLike, fields: Mapping[str, str] | Sequence[str],
              units: Mapping[str, str] | None = None, ts: float | None = None,
              start: float | None = None, stop: float | None = None) -> FlightData:
    """Load signals from a PX4 ULog file (pyulog).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.ulg`` file.
    fields : dict of str -> str, or list of str
        Output signal name -> ``"topic.field"``, e.g.
        ``{"y": "vehicle_local_position.x",
        "u": "vehicle_local_position_setpoint.acceleration[0]"}``. A topic logged in several
        instances is addressed as ``"topic:1.field"`` (instance 0 when omitted).
    units : dict of str -> str, optional
        Unit of each output signal. Default: a small table of common PX4 fields (positions
        m, velocities m/s, accelerations m/s^2, angles rad), else "".
    ts : float, optional
        Sample time of the common grid, s; default the finest median step of the topics.
    start, stop : float, optional
        Keep ``start <= t <= stop``, s since boot (the ULog ``timestamp`` clock).

    Returns
    -------
    FlightData
        Time in s since boot (``timestamp`` in µs / 1e6). ``metadata`` holds ``format``,
        ``fields``, the original topic rates, the vehicle/software info strings, the
        ``dropouts`` (count, total ms) and pyulog's ``file_corruption`` flag.

    Raises
    ------
    SignalError
        Missing or unreadable file, a topic, instance or field not in the log (the message
        lists what is there), non-finite values, duplicated or decreasing time stamps, or an
        empty selection.
    """
    from pyulog import ULog

    source = _source_of(path)
    spec = _mapping(fields, "fields", source)
    parsed = {n: _parse_ulog_spec(s, n, source) for n, s in spec.items()}
    units_arg = _check_units(units, list(spec), source)
    ts = _check_ts(ts, source)
    start, stop = _check_window(start, stop, source)
    _check_file(source)
    topics = sorted({topic for topic, _, _ in parsed.values()})
    try:
        ulog = ULog(source, topics, disable_str_exceptions=True)
    except Exception as exc:  # pyulog raises ULogException, struct.error, ... on a bad file
        raise SignalError(f"{source}: cannot read as a PX4 ULog file ({type(exc).__name__}: {exc})") from None
    datasets = {(d.name, d.multi_id): d for d in ulog.data_list}
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    what: dict[str, str] = {}
    sig_units: dict[str, str] = {}
    for name, (topic, inst, field) in parsed.items():
        label = f"{topic}:{inst}" if inst else topic
        d = datasets.get((topic, inst))
        if d is None:
            insts = sorted(k[1] for k in datasets if k[0] == topic)
            if insts:
                raise SignalError(f"{source}: signal `{name}`: topic {topic!r} has no instance {inst}; "
                                  f"instances logged: {insts}")
            have = _ulog_topics(source)
            if not have:
                raise SignalError(f"{source}: signal `{name}`: topic {topic!r} not in the log; the log holds "
                                  f"no logged data at all (truncated or header-only file?)")
            raise SignalError(f"{source}: signal `{name}`: topic {topic!r} not in the log; topics with "
                              f"data: {_listing(have)}")
        if field not in d.data or field == "timestamp":
            present = [f for f in d.data if f != "timestamp"]
            raise SignalError(f"{source}: signal `{name}`: topic {label!r} has no field {field!r}; "
                              f"fields: {_listing(present)}")
        t = np.asarray(d.data["timestamp"], dtype=float) * 1e-6
        x = np.asarray(d.data[field], dtype=float)
        series[name] = (t, x)
        what[name] = f"signal `{name}` ({label}.{field})"
        sig_units[name] = units_arg.get(name, _px4_unit(topic, field))

    info = {k: v for k, v in ulog.msg_info_dict.items()
            if k in ("sys_name", "ver_hw", "ver_sw", "ver_sw_release", "sys_uuid", "sys_os_name")}
    drop_ms = [float(getattr(dr, "duration", 0.0)) for dr in ulog.dropouts]
    meta = {"format": "ulog", "fields": dict(spec), "info": info,
            "start_timestamp_s": ulog.start_timestamp * 1e-6,
            "dropouts": {"count": len(drop_ms), "total_ms": float(sum(drop_ms))},
            "file_corruption": bool(ulog.file_corruption)}
    return _from_series(series, what, sig_units, meta, ts, start, stop, source)


# --------------------------------------------------------------------------------------
# ArduPilot DataFlash
# --------------------------------------------------------------------------------------

_DF_SPEC = re.compile(r"^([A-Za-z0-9_]+)(?:\[(\w+)\]|:(\w+))?\.([A-Za-z0-9_]+)$")


class _Sink(io.TextIOBase):
    """Swallows what DFReader prints about skipped bytes, counting the lines."""

    def __init__(self) -> None:
        self.lines = 0
        self.first: str | None = None

    def writable(self) -> bool:
        return True

    def write(self, s: str) -> int:
        if s.strip():
            self.lines += s.count("\n") or 1
            if self.first is None:
                self.first = s.strip()
        return len(s)


@contextlib.contextmanager
def _quiet() -> Iterator[_Sink]:
    sink = _Sink()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        yield sink


def _open_dataflash(source: str) -> Any:
    from pymavlink import DFReader

    with open(source, "rb") as fh:
        head = fh.read(3)
    if head[:2] == bytes([0xA3, 0x95]):
        if head[2:3] != bytes([0x80]):
            raise SignalError(f"{source}: DataFlash binary does not start with a FMT message (type 0x80, "
                              f"got 0x{head[2]:02x}); the file is corrupt")
        return DFReader.DFReader_binary(source, zero_time_base=False)
    try:
        with open(source, encoding="utf-8") as fh:
            text_head = fh.read(8000)
    except (UnicodeDecodeError, OSError):
        text_head = ""
    if text_head.lstrip().startswith("FMT,"):
        return DFReader.DFReader_text(source, zero_time_base=False)
    raise SignalError(f"{source}: not an ArduPilot DataFlash log: a binary log starts with bytes "
                      f"A3 95 80 (got {head.hex(' ').upper()}), a text log with a 'FMT,' line")


def _df_catalogue(reader: Any) -> tuple[dict[str, Any], dict[str, int]]:
    """Formats by message name and message counts by name."""
    fmts = {fmt.name: fmt for fmt in reader.formats.values()}
    counts: dict[str, int] = {}
    if isinstance(reader.counts, dict):  # text reader: keyed by name
        counts = {str(k): int(v) for k, v in reader.counts.items()}
    else:
        for type_id, fmt in reader.formats.items():
            if isinstance(type_id, int) and 0 <= type_id < len(reader.counts):
                counts[fmt.name] = int(reader.counts[type_id])
    return fmts, counts


def load_dataflash(path: str | os.PathLike, fields: Mapping[str, str] | Sequence[str],
                   units: Mapping[str, str] | None = None, ts: float | None = None,
                   start: float | None = None, stop: float | None = None) -> FlightData:
    """Load signals from an ArduPilot DataFlash log (binary ``.bin`` or text ``.log``).

    Parameters
    ----------
    path : str or os.PathLike
        The log file.
    fields : dict of str -> str, or list of str
        Output signal name -> ``"TYPE.Field"``, e.g. ``{"y": "PSCN.PN", "lat": "POS.Lat"}``.
        Messages with an instance column (declared by ``#`` in the log's FMTU units) are
        selected as ``"IMU[1].AccX"`` (or ``"IMU:1.AccX"``); without an instance all
        messages of the type are used.
    units : dict of str -> str, optional
        Unit of each output signal; default: the unit the log declares (FMTU/UNIT
        messages, with its multiplier prefix, e.g. ``"m"``, ``"cm"``) or "" when it declares none.
    ts : float, optional
        Sample time of the common grid, s; default the finest median step of the types.
    start, stop : float, optional
        Keep ``start <= t <= stop``, s since boot (the ``TimeUS`` clock).

    Returns
    -------
    FlightData
        Time from each message's ``TimeUS`` (µs / 1e6; ``TimeMS`` / 1e3 in old logs).
        Values are as pymavlink scales them (e.g. ``Lat`` in degrees). ``metadata`` holds
        ``format``, ``fields``, ``message_counts`` and ``skipped_reports`` (lines DFReader
        printed about bytes it skipped).

    Raises
    ------
    SignalError
        Missing, empty or corrupt file, a message type, field or instance not in the log
        (the message lists what is there), a text field, non-finite values, duplicated or
        decreasing time stamps, or an empty selection.
    """
    source = _source_of(path)
    spec = _mapping(fields, "fields", source)
    parsed: dict[str, tuple[str, str | None, str]] = {}
    for n, s in spec.items():
        m = _DF_SPEC.match(s.strip())
        if not m:
            raise SignalError(f"{source}: signal `{n}`: field {s!r} not of the form 'TYPE.Field' or "
                              f"'TYPE[instance].Field' (e.g. 'PSCN.PN', 'IMU[1].AccX')")
        parsed[n] = (m.group(1), m.group(2) if m.group(2) is not None else m.group(3), m.group(4))
    units_arg = _check_units(units, list(spec), source)
    ts = _check_ts(ts, source)
    start, stop = _check_window(start, stop, source)
    _check_file(source)

    with _quiet() as sink:
        try:
            reader = _open_dataflash(source)
        except SignalError:
            raise
        except Exception as exc:  # DFReader raises struct.error, KeyError, ... on corrupt data
            raise SignalError(f"{source}: cannot read as a DataFlash log ({type(exc).__name__}: {exc})") from None
        try:
            fmts, counts = _df_catalogue(reader)
            present = sorted(n for n, c in counts.items() if c > 0 and n != "FMT")
            if not present:
                raise SignalError(f"{source}: no data messages in the DataFlash log (only format definitions); "
                                  f"the file is truncated or corrupt")
            time_col: dict[str, str] = {}
            for name, (mtype, inst, field) in parsed.items():
                if mtype not in fmts or counts.get(mtype, 0) == 0:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} not in the log; "
                                      f"types with data: {_listing(present)}")
                fmt = fmts[mtype]
                if field not in fmt.columns:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no field "
                                      f"{field!r}; fields: {_listing(fmt.columns)}")
                if inst is not None and fmt.instance_field is None:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no instance "
                                      f"column in this log (no '#' in its FMTU units); use {mtype}.{field}")
                tc = "TimeUS" if "TimeUS" in fmt.columns else "TimeMS" if "TimeMS" in fmt.columns else None
                if tc is None:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no TimeUS or "
                                      f"TimeMS column; fields: {_listing(fmt.columns)}")
                time_col[mtype] = tc

            wanted: dict[str, list[str]] = {}
            for mtype, _, field in parsed.values():
                wanted.setdefault(mtype, [])
                for f in (time_col[mtype], field, fmts[mtype].instance_field):
                    if f is not None and f not in wanted[mtype]:
                        wanted[mtype].append(f)
            rows: dict[str, list[list[Any]]] = {mtype: [] for mtype in wanted}
            reader.rewind()
            while True:
                msg = reader.recv_match(type=list(wanted))
                if msg is None:
                    break
                mtype = msg.get_type()
                if mtype in rows:
                    rows[mtype].append([getattr(msg, f) for f in wanted[mtype]])
        except SignalError:
            raise
        except Exception as exc:
            raise SignalError(f"{source}: cannot read the DataFlash messages ({type(exc).__name__}: {exc})") from None
        finally:
            with contextlib.suppress(Exception):
                reader.close()

    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    what: dict[str, str] = {}
    sig_units: dict[str, str] = {}
    for name, (mtype, inst, field) in parsed.items():
        label = f"{mtype}[{inst}].{field}" if inst is not None else f"{mtype}.{field}"
        what[name] = f"signal `{name}` ({label})"
        cols = wanted[mtype]
        recs = rows[mtype]
        ifield = fmts[mtype].instance_field
        if inst is not None:
            k = cols.index(ifield)
            found = sorted({str(r[k]) for r in recs})
            recs = [r for r in recs if str(r[k]) == inst]
            if not recs:
                raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no instance {inst} "
                                  f"({ifield} values logged: {found})")
        if len(recs) < 2:
            raise SignalError(f"{source}: signal `{name}`: {len(recs)} message(s) of {label}; expected at least 2")
        j = cols.index(field)
        try:
            x = np.array([r[j] for r in recs], dtype=float)
        except (TypeError, ValueError):
            raise SignalError(f"{source}: signal `{name}`: field {label} holds text ({recs[0][j]!r}), "
                              f"expected numbers") from None
        scale = 1e-6 if time_col[mtype] == "TimeUS" else 1e-3
        t = np.array([r[0] for r in recs], dtype=float) * scale
        series[name] = (t, x)
        try:
            declared = fmts[mtype].get_unit(field)
        except Exception:
            declared = ""
        sig_units[name] = units_arg.get(name, declared or "")
    meta = {"format": "dataflash", "fields": dict(spec),
            "message_counts": {mtype: counts.get(mtype, 0) for mtype in wanted},
            "skipped_reports": sink.lines}
    return _from_series(series, what, sig_units, meta, ts, start, stop, source)


# --------------------------------------------------------------------------------------
# dispatch
# --------------------------------------------------------------------------------------

def load_flight(path: str | os.PathLike, fields: Mapping[str, str] | Sequence[str], time: str | None = None,
                **kw: Any) -> FlightData:
    """Load a flight log, choosing the loader from the file suffix.

    ``.csv`` -> :func:`load_csv`, ``.parquet``/``.pq`` -> :func:`load_parquet`, ``.ulg`` ->
    :func:`load_ulog`, ``.bin``/``.log`` -> :func:`load_dataflash` (suffixes are matched
    without regard to case).

    Parameters
    ----------
    path : str or os.PathLike
    fields : dict of str -> str, or list of str
        Signal name -> column (CSV, Parquet), ``"topic.field"`` (ULog) or ``"TYPE.Field"``
        (DataFlash).
    time : str, optional
        Time column of a CSV/Parquet table (default ``"time"``); logs carry their own clock,
        so it must be None for them.
    **kw
        ``units``, ``ts``, ``start``, ``stop``: passed on.

    Raises
    ------
    SignalError
        Unknown suffix (the message lists the valid ones), ``time`` given for a log, or
        whatever the chosen loader raises.
    """
    source = _source_of(path)
    suffix = Path(source).suffix.lower()
    if suffix not in SUFFIXES:
        raise SignalError(f"{source}: unknown file suffix {Path(source).suffix!r}; valid: "
                          f"{', '.join(SUFFIXES)}")
    loader = SUFFIXES[suffix]
    allowed = {"units", "ts", "start", "stop"}
    extra = sorted(set(kw) - allowed)
    if extra:
        raise SignalError(f"{source}: unknown keyword argument(s) {extra}; valid: time, {', '.join(sorted(allowed))}")
    if loader in ("load_csv", "load_parquet"):
        fn = load_csv if loader == "load_csv" else load_parquet
        return fn(path, fields, time="time" if time is None else time, **kw)
    if time is not None:
        raise SignalError(f"{source}: `time`: got {time!r}; a {suffix} log carries its own clock "
                          f"(TimeUS/timestamp), so `time` applies to .csv/.parquet only")
    fn = load_ulog if loader == "load_ulog" else load_dataflash
    return fn(path, fields, **kw)
