"""ArduPilot DataFlash loader (:func:`load_dataflash`, via pymavlink's DFReader).

Reads binary ``.bin`` and text ``.log`` logs. Signals are addressed as ``"TYPE.Field"``
(``"TYPE[instance].Field"`` for message types with an instance column). Time is in s since
boot (each message's ``TimeUS`` / 1e6, or ``TimeMS`` / 1e3 in old logs); it is **not**
shifted to start at zero, so ``start`` and ``stop`` are read on that same clock. Message
types logged at different rates are linearly interpolated onto one grid whose step is the
finest median step among them (or ``ts`` when given) and which spans the time all of them
overlap; with ``start`` the grid starts exactly there when every selected signal has data
at that time (``t = start + k ts``). What DFReader prints about skipped bytes is kept off the
console (:func:`~.guard.captured_output`): its Python lines are counted in
``metadata["skipped_reports"]``, its compiled indexer's (a line per damaged byte, straight to
file descriptor 2) discarded; ``metadata["damaged_bytes"]`` counts the bytes of a binary log in
no message. Reading is linear in the file's size, damaged or not (a 1 MiB damaged tail: about a second).

Every error is a :class:`~ilcdob.errors.SignalError` whose message names the file, the
signal and its message type and field, the value received and what is valid.
"""

from __future__ import annotations

import contextlib
import os
import re
from typing import Any, Mapping, Sequence

import numpy as np

from ilcdob.errors import SignalError
from ilcdob.extras import require
from ilcdob.signals import FlightData

from .common import (check_file, check_ts, check_units, check_window, from_series, listing, signal_mapping,
                     source_of)
from .guard import captured_output


__all__ = ["load_dataflash"]

_DF_SPEC = re.compile(r"^([A-Za-z0-9_]+)(?:\[(\w+)\]|:(\w+))?\.([A-Za-z0-9_]+)$")


def _open_dataflash(source: str) -> Any:
    DFReader = require("pymavlink.DFReader", "logs", f"{source}: reading an ArduPilot DataFlash log")

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


def _damaged_bytes(reader: Any) -> int | None:
    """Bytes of a binary log in no message the index found (damage, or a cut last message); None for text logs."""
    if isinstance(reader.counts, dict) or not hasattr(reader, "data_len"):
        return None
    covered = sum(int(reader.counts[t]) * int(fmt.len) for t, fmt in reader.formats.items()
                  if isinstance(t, int) and 0 <= t < len(reader.counts))
    return max(0, int(reader.data_len) - covered)


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
        ``format``, ``fields``, ``message_counts``, ``skipped_reports`` (lines DFReader
        printed from Python about bytes it skipped) and ``damaged_bytes`` (binary logs: bytes in
        no message of the index, damage or a cut last message; None for text logs).

    Raises
    ------
    SignalError
        Missing, empty or corrupt file, a message type, field or instance not in the log
        (the message lists what is there), a text field, non-finite values, duplicated or
        decreasing time stamps, or an empty selection.
    """
    source = source_of(path)
    spec = signal_mapping(fields, "fields", source)
    parsed: dict[str, tuple[str, str | None, str]] = {}
    for n, s in spec.items():
        m = _DF_SPEC.match(s.strip())
        if not m:
            raise SignalError(f"{source}: signal `{n}`: field {s!r} not of the form 'TYPE.Field' or "
                              f"'TYPE[instance].Field' (e.g. 'PSCN.PN', 'IMU[1].AccX')")
        parsed[n] = (m.group(1), m.group(2) if m.group(2) is not None else m.group(3), m.group(4))
    units_arg = check_units(units, list(spec), source)
    ts = check_ts(ts, source)
    start, stop = check_window(start, stop, source)
    check_file(source)

    with captured_output() as sink:
        try:
            reader = _open_dataflash(source)
        except SignalError:
            raise
        except Exception as exc:  # DFReader raises struct.error, KeyError, ... on corrupt data
            raise SignalError(f"{source}: cannot read as a DataFlash log ({type(exc).__name__}: {exc})") from None
        try:
            fmts, counts = _df_catalogue(reader)
            damaged = _damaged_bytes(reader)
            present = sorted(n for n, c in counts.items() if c > 0 and n != "FMT")
            if not present:
                raise SignalError(f"{source}: no data messages in the DataFlash log (only format definitions); "
                                  f"the file is truncated or corrupt")
            time_col: dict[str, str] = {}
            for name, (mtype, inst, field) in parsed.items():
                if mtype not in fmts or counts.get(mtype, 0) == 0:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} not in the log; "
                                      f"types with data: {listing(present)}")
                fmt = fmts[mtype]
                if field not in fmt.columns:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no field "
                                      f"{field!r}; fields: {listing(fmt.columns)}")
                if inst is not None and fmt.instance_field is None:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no instance "
                                      f"column in this log (no '#' in its FMTU units); use {mtype}.{field}")
                tc = "TimeUS" if "TimeUS" in fmt.columns else "TimeMS" if "TimeMS" in fmt.columns else None
                if tc is None:
                    raise SignalError(f"{source}: signal `{name}`: message type {mtype!r} has no TimeUS or "
                                      f"TimeMS column; fields: {listing(fmt.columns)}")
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
            "skipped_reports": sink.lines, "damaged_bytes": damaged}
    return from_series(series, what, sig_units, meta, ts, start, stop, source)
