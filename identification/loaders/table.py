"""Table loaders: comma-separated text (:func:`load_csv`) and Parquet (:func:`load_parquet`).

Both read a time column and one column per signal, and share the handling of the time
column:

* its unit comes from the ``units`` argument (key ``"time"``), else from the file (a
  ``# units:`` comment line in CSV, the ``ilcdob.units`` schema metadata in Parquet),
  else s; ``ms``, ``us`` and ``ns`` are converted to s. A column whose unit is not stated
  and whose median step is :data:`UNSTATED_UNIT_STEP_S` or more draws a
  :class:`UserWarning` (milliseconds read as seconds, most likely);
* the file's own samples are kept when the time column is uniform to within
  :data:`SNAP_RTOL` of a step (the stamps are then replaced by the exact grid
  ``t0 + k ts``, which absorbs the rounding of a text writer); otherwise, or when ``ts``
  asks for another step, the signals are linearly interpolated onto a uniform grid
  (:meth:`FlightData.from_samples`);
* a clock at Unix-epoch magnitude (>= :data:`EPOCH_SHIFT_S`, or an Arrow timestamp
  column) is shifted to start at the file's first stamp, kept in
  ``metadata["time_origin_s"]`` (float64 cannot hold a uniform grid at 1e9 s to the
  precision :class:`FlightData` checks); ``start``/``stop`` are still given on the
  file's clock.

Every error is a :class:`~ilcdob.errors.SignalError` whose message names the file, the
signal and its column, the value received and what is valid.
"""

from __future__ import annotations

import csv
import json
import os
import re
import warnings
from decimal import Decimal, InvalidOperation
from typing import Any, Mapping, Sequence

import numpy as np

from ilcdob.errors import SignalError
from ilcdob.extras import require
from ilcdob.inputs import MAX_LOG_BYTES, read_text
from ilcdob.signals import FlightData

from .common import (check_file, check_stamps, check_ts, check_units, check_values, check_window,
                     checked_segment, listing, signal_mapping, source_of, window_slice)


__all__ = ["load_csv", "load_parquet", "SNAP_RTOL", "EPOCH_SHIFT_S", "UNSTATED_UNIT_STEP_S"]

#: A table's time column counts as uniform when every stamp lies within this fraction of a
#: sample step of the straight line ``t0 + k ts``; it is then snapped onto that line.
SNAP_RTOL = 1e-3

#: A table time column whose values reach this magnitude (s; a Unix-epoch clock) is shifted
#: to start at 0, the origin kept in ``metadata["time_origin_s"]``: float64 cannot hold a
#: uniform grid at 1e9 s to the precision :class:`FlightData` checks.
EPOCH_SHIFT_S = 1e7

#: Time units accepted for a table's time column (factor to s).
_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "ns": 1e-9}


# --------------------------------------------------------------------------------------
# time column and grid
# --------------------------------------------------------------------------------------

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
    sl = window_slice(t, start, stop, source, tcol)
    t = t[sl]
    rows = rows[sl] if rows is not None else None
    check_stamps(t, source, tcol, rows)
    cols = {n: x[sl] for n, x in cols.items()}
    for n, x in cols.items():
        check_values(x, t, source, what[n], rows)
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
    return checked_segment(fd, start, stop)


# --------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------

_UNITS_LINE = re.compile(r"^\s*#\s*units\s*:\s*(.*)$", re.IGNORECASE)
#: ``# time: ms``: a comment naming one column's time unit (s, ms, us or ns) also states it.
_TIME_UNIT_LINE = re.compile(r"^\s*#\s*([A-Za-z_][\w.\[\]]*)\s*:\s*(s|ms|us|ns)\s*$")


def _comment_units(line: str) -> dict[str, str]:
    """Units stated by a comment line: ``# units: time=ms, x=m`` or ``# time: ms``."""
    m = _UNITS_LINE.match(line)
    if m:
        units = {}
        for item in m.group(1).split(","):
            if "=" in item:
                k, v = item.split("=", 1)
                units[k.strip()] = v.strip()
        return units
    m = _TIME_UNIT_LINE.match(line)
    return {m.group(1): m.group(2)} if m else {}


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
    source = source_of(path)
    cols = signal_mapping(columns, "columns", source)
    if not isinstance(time, str) or not time:
        raise SignalError(f"{source}: `time`: got {time!r}, expected the name of the time column")
    units_arg = check_units(units, list(cols), source, allow_time=True)
    ts = check_ts(ts, source)
    start, stop = check_window(start, stop, source)
    check_file(source)
    return source, cols, units_arg, ts, start, stop


def load_csv(path: str | os.PathLike, columns: Mapping[str, str] | Sequence[str], time: str = "time",
             units: Mapping[str, str] | None = None, ts: float | None = None,
             start: float | None = None, stop: float | None = None) -> FlightData:
    """Load signals from a CSV file with a header row.

    Lines whose first non-blank character is ``#`` are comments; a comment
    ``# units: time=s, x=m, ...`` (what :meth:`FlightData.to_csv` writes) gives the unit of
    each column, and ``# time: ms`` the unit of one time column (s, ms, us or ns). Blank lines
    are skipped. Files with comments only before the header and plain numeric cells are read
    with pyarrow's CSV reader; any other file line by line, with messages naming the line.

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

    text = read_text(source, "flight log", limit=MAX_LOG_BYTES, error=SignalError, hint="expected CSV text")
    fast = _fast_csv(text, time, cols)
    if fast is not None:
        t, values, file_units, data_lines = fast
        return _csv_result(source, t, values, cols, time, units_arg, file_units, data_lines, 0.0, ts, start, stop)
    lines = text.splitlines()
    del text

    file_units: dict[str, str] = {}
    body: list[str] = []
    line_no: list[int] = []
    for i, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            file_units.update(_comment_units(stripped))
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
                          f"columns present: {listing(header)}")
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

    t = out[time]
    origin = 0.0
    if np.isfinite(t[0]) and abs(t[0]) >= EPOCH_SHIFT_S:
        # subtract the first stamp in decimal arithmetic: exact differences of the text
        j = index[time]
        try:
            first = Decimal(data_rows[0][j].strip())
            t = np.array([float(Decimal(row[j].strip()) - first) for row in data_rows])
            origin = float(first)
        except (InvalidOperation, ValueError):
            pass
    return _csv_result(source, t, out, cols, time, units_arg, file_units, data_lines, origin, ts, start, stop)


def _csv_result(source: str, t: np.ndarray, values: dict[str, np.ndarray], cols: dict[str, str], time: str,
                units_arg: dict[str, str], file_units: dict[str, str], data_lines: np.ndarray, origin: float,
                ts: float | None, start: float | None, stop: float | None) -> FlightData:
    """The FlightData of parsed CSV columns (time in the file's unit, ``origin`` subtracted)."""
    tunit = units_arg.get("time", file_units.get(time, "s"))
    scale = _time_scale(tunit, source, time)
    t = t * scale
    _warn_unstated_unit(t, "time" in units_arg or time in file_units, source, time)
    sig_units = {n: units_arg.get(n, file_units.get(c, "")) for n, c in cols.items()}
    what = {n: f"signal `{n}` (column `{c}`)" for n, c in cols.items()}
    meta = {"format": "csv", "columns": dict(cols), "time_column": time}
    return _from_table(t, {n: values[c] for n, c in cols.items()}, what, sig_units, meta, ts, start, stop,
                       source, rows=data_lines, origin=origin * scale)


def _fast_csv(text: str, time: str, cols: dict[str, str]) -> tuple | None:
    """Parse the common case with pyarrow's CSV reader: comment lines only before the header,
    no blank or comment line in the data, every wanted cell a number, the first stamp small
    enough for binary floating point. Anything else returns None, and the line-by-line parser
    (slower; exact messages with line numbers) reads the file."""
    import io

    try:  # the fast path; without pyarrow (the logs extra) the line-by-line parser reads every file
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:
        return None

    pos, line_no, file_units = 0, 0, {}
    while True:
        end = text.find("\n", pos)
        if end < 0:
            return None
        line = text[pos:end].strip()
        line_no += 1
        if line and not line.startswith("#"):
            break
        file_units.update(_comment_units(line))
        pos = end + 1
    body = text[pos:]
    if "#" in body or '"' in body or "\n\n" in body.replace("\r\n", "\n").rstrip("\n"):
        return None
    header = [h.strip() for h in text[pos:end].split(",")]
    wanted = [time, *cols.values()]
    if len(set(header)) != len(header) or any(c not in header for c in wanted):
        return None
    try:
        table = pacsv.read_csv(io.BytesIO(body.encode("utf-8")),
                               read_options=pacsv.ReadOptions(column_names=header, skip_rows=1),
                               convert_options=pacsv.ConvertOptions(
                                   include_columns=list(dict.fromkeys(wanted)),
                                   column_types={c: pa.float64() for c in wanted}))
    except (pa.ArrowInvalid, ValueError):
        return None
    if table.num_rows < 2 or any(table.column(c).null_count for c in wanted):
        return None
    values = {c: table.column(c).to_numpy() for c in wanted}
    if not np.isfinite(values[time][0]) or abs(values[time][0]) >= EPOCH_SHIFT_S:
        return None
    return values[time], values, file_units, line_no + 1 + np.arange(table.num_rows)


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
    source, cols, units_arg, ts, start, stop = _tabular_arguments(path, columns, time, units, ts, start, stop)
    pq = require("pyarrow.parquet", "logs", f"{source}: reading a Parquet file")
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
                          f"columns present: {listing(names)}")
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
