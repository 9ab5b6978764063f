"""Loaders of flight logs into :class:`~ilcdob.signals.FlightData`.

One function per source, each returning a :class:`FlightData` on a uniform time grid:

* :func:`load_csv` -- comma-separated text with a header row (our own
  :meth:`FlightData.to_csv` output, or any logger's CSV);
* :func:`load_parquet` -- Parquet tables (pyarrow);
* :func:`load_ulog` -- PX4 ULog ``.ulg`` files (pyulog);
* :func:`load_dataflash` -- ArduPilot DataFlash logs, binary ``.bin`` or text ``.log``
  (pymavlink's DFReader);
* :func:`load_flight` -- dispatch on the file suffix (:data:`SUFFIXES`).

Modules
-------
* :mod:`.table` -- :func:`load_csv` and :func:`load_parquet`, with the handling of a
  table's time column (unit, uniform-grid snapping, Unix-epoch clocks);
* :mod:`.ulog` -- :func:`load_ulog`;
* :mod:`.dataflash` -- :func:`load_dataflash`;
* :mod:`.common` -- what they share: signal selection, argument, time-stamp and value
  checks, and the common grid of signals logged at different rates.
* :mod:`.guard` -- the bounds on the third-party log parsers: a read budget that ends the
  parse of a damaged ULog file in time proportional to its size, and the capture of what
  pyulog and pymavlink print.

Conventions
-----------
Time is in s: for ULog from the log's start (``timestamp - start_timestamp``, the absolute origin kept in
``metadata["start_timestamp_s"]``), for DataFlash since boot (its ``TimeUS`` clock), for CSV/Parquet the time
column as written; ``start`` and ``stop`` (s) are read on that same clock. Signals from topics or message types logged at
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

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from ilcdob.errors import SignalError
from ilcdob.signals import FlightData

from .common import source_of
from .dataflash import load_dataflash
from .table import EPOCH_SHIFT_S, SNAP_RTOL, UNSTATED_UNIT_STEP_S, load_csv, load_parquet
from .ulog import load_ulog


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

#: File suffix (lower case) -> loader name, used by :func:`load_flight`.
SUFFIXES: dict[str, str] = {
    ".csv": "load_csv",
    ".parquet": "load_parquet",
    ".pq": "load_parquet",
    ".ulg": "load_ulog",
    ".bin": "load_dataflash",
    ".log": "load_dataflash",
}


def load_flight(path: str | os.PathLike, fields: Mapping[str, str] | Sequence[str], time: str | None = None,
                **kw: Any) -> FlightData:
    """Load a flight log, choosing the loader from the file suffix.

    ``.csv`` -> :func:`load_csv`, ``.parquet``/``.pq`` -> :func:`load_parquet`, ``.ulg`` ->
    :func:`load_ulog`, ``.bin``/``.log`` -> :func:`load_dataflash` (suffixes are matched
    without regard to case).

    Parameters
    ----------
    path : str or os.PathLike
        The log file; its suffix chooses the loader (:data:`SUFFIXES`).
    fields : dict of str -> str, or list of str
        Signal name -> column (CSV, Parquet), ``"topic.field"`` (ULog) or ``"TYPE.Field"``
        (DataFlash).
    time : str, optional
        Time column of a CSV/Parquet table (default ``"time"``); logs carry their own clock,
        so it must be None for them.
    **kw
        ``units``, ``ts``, ``start``, ``stop``: passed on.

    Returns
    -------
    FlightData
        What the chosen loader returns.

    Raises
    ------
    SignalError
        Unknown suffix (the message lists the valid ones), ``time`` given for a log, or
        whatever the chosen loader raises.
    """
    source = source_of(path)
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
