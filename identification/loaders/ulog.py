"""PX4 ULog loader (:func:`load_ulog`, via pyulog).

Signals are addressed as ``"topic.field"`` (``"topic:instance.field"`` for a topic
logged in several instances). Time is in s since the log's start: the ULog ``timestamp`` clock (µs since
boot, or since the epoch on some logs) less the file's ``start_timestamp``, which ``metadata`` keeps in s
(``start_timestamp_s``); ``start`` and ``stop`` are read on that clock, so a window is typed as seen in a log
viewer that counts from the start. A topic may log a few samples stamped just before ``start_timestamp``
(negative times of a few ms). Topics logged at different rates are linearly interpolated onto one grid whose
step is the finest median step among them (or ``ts`` when given) and which spans the time
all of them overlap; with ``start`` the grid starts exactly there when every selected
signal has data at that time (``t = start + k ts``). Units come from a small table of
common PX4 fields, as ULog files carry none of their own.

A damaged file ends in bounded time: pyulog reads it through a byte budget
(:class:`~.guard.BudgetedFile`, about 16 times the file's size), and what it prints about
damaged messages is swallowed and counted (``metadata["parser_reports"]``).

Every error is a :class:`~ilcdob.errors.SignalError` whose message names the file, the
signal and its topic and field, the value received and what is valid.
"""

from __future__ import annotations

import os
import re
from typing import Any, Mapping, Sequence

import numpy as np

from ilcdob.channel_gain import ChannelGain
from ilcdob.errors import SignalError, SpecError
from ilcdob.extras import require
from ilcdob.signals import FlightData

from .common import (check_file, check_ts, check_units, check_window, from_series, listing, signal_mapping,
                     source_of)
from .guard import BudgetedFile, CapturedOutput, ReadBudgetExceeded, captured_output


__all__ = ["load_ulog", "px4_cascade_gains", "PX4_CASCADE_PARAMETERS"]

#: The multicopter position controller's gains per axis (PX4 1.12 on: velocity gains in acceleration units), in
#: the order of :meth:`ilcdob.channel_gain.ChannelGain.cascade`: position P, velocity P, velocity I.
PX4_CASCADE_PARAMETERS = {"x": ("MPC_XY_P", "MPC_XY_VEL_P_ACC", "MPC_XY_VEL_I_ACC"),
                          "y": ("MPC_XY_P", "MPC_XY_VEL_P_ACC", "MPC_XY_VEL_I_ACC"),
                          "z": ("MPC_Z_P", "MPC_Z_VEL_P_ACC", "MPC_Z_VEL_I_ACC")}

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


_ULOG_SPEC = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?::(\d+))?\.(\S+)$")


def _parse_ulog_spec(spec: str, name: str, source: str) -> tuple[str, int, str]:
    m = _ULOG_SPEC.match(spec.strip())
    if not m:
        raise SignalError(f"{source}: signal `{name}`: field {spec!r} not of the form 'topic.field' or "
                          f"'topic:instance.field' (e.g. 'vehicle_local_position.x')")
    return m.group(1), int(m.group(2) or 0), m.group(3)


def _parse(source: str, topics: list[str] | None) -> tuple[Any, CapturedOutput]:
    """pyulog's parse of ``source`` (only ``topics``; None: all), within the read budget and quiet;
    returns the ULog object and what pyulog printed.

    Raises
    ------
    SignalError
        The file is not a ULog file, or its message stream is damaged beyond the read budget.
    """
    ULog = require("pyulog", "logs", f"{source}: reading a PX4 ULog file").ULog

    with captured_output() as printed, BudgetedFile(source) as fh:
        try:
            ulog = ULog(fh, topics, disable_str_exceptions=True)
        except ReadBudgetExceeded as exc:
            raise SignalError(
                f"{source}: the ULog message stream is damaged: parsing read {exc.read / 2**20:.0f} MiB of this "
                f"{exc.size / 2**20:.3g} MiB file and was still resynchronising at byte {exc.position} (a valid "
                f"log is read about once): the file is damaged at or before that byte. Next step: copy the log "
                f"from the vehicle again; a copy cut where the damage starts loads the part before it"
            ) from None
        except Exception as exc:  # pyulog raises ULogException, struct.error, ... on a bad file
            raise SignalError(f"{source}: cannot read as a PX4 ULog file ({type(exc).__name__}: {exc})") from None
    return ulog, printed


def _ulog_topics(source: str) -> list[str]:
    """Every topic (with instance when > 0) that has data in the file; for error messages."""
    try:
        ulog, _ = _parse(source, None)
    except SignalError:
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
        Keep ``start <= t <= stop``, s since the log's start (``timestamp - start_timestamp``).

    Returns
    -------
    FlightData
        Time in s since the log's start (``(timestamp - start_timestamp)`` in µs / 1e6). ``metadata`` holds
        ``start_timestamp_s`` (the absolute origin), ``format``,
        ``fields``, the original topic rates, the vehicle/software info strings, the
        ``dropouts`` (count, total ms), pyulog's ``file_corruption`` flag and ``parser_reports``
        (lines pyulog printed about damaged messages, swallowed).

    Raises
    ------
    SignalError
        Missing or unreadable file, a message stream damaged beyond the read budget
        (:func:`~.guard.read_budget`), a topic, instance or field not in the log (the message
        lists what is there), non-finite values, duplicated or decreasing time stamps, or an
        empty selection.
    """
    source = source_of(path)
    spec = signal_mapping(fields, "fields", source)
    parsed = {n: _parse_ulog_spec(s, n, source) for n, s in spec.items()}
    units_arg = check_units(units, list(spec), source)
    ts = check_ts(ts, source)
    start, stop = check_window(start, stop, source)
    check_file(source)
    ulog, printed = _parse(source, sorted({topic for topic, _, _ in parsed.values()}))
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
                              f"data: {listing(have)}")
        if field not in d.data or field == "timestamp":
            present = [f for f in d.data if f != "timestamp"]
            raise SignalError(f"{source}: signal `{name}`: topic {label!r} has no field {field!r}; "
                              f"fields: {listing(present)}")
        t = (np.asarray(d.data["timestamp"], dtype=float) - ulog.start_timestamp) * 1e-6  # s from the log's start
        x = np.asarray(d.data[field], dtype=float)
        series[name] = (t, x)
        what[name] = f"signal `{name}` ({label}.{field})"
        sig_units[name] = units_arg.get(name, _px4_unit(topic, field))

    info = {k: v for k, v in ulog.msg_info_dict.items()
            if k in ("sys_name", "ver_hw", "ver_sw", "ver_sw_release", "sys_uuid", "sys_os_name")}
    drop_ms = [float(getattr(dr, "duration", 0.0)) for dr in ulog.dropouts]
    meta = {"format": "ulog", "fields": dict(spec), "info": info,
            "start_timestamp_s": ulog.start_timestamp * 1e-6, "time": "s since the log's start (start_timestamp_s)",
            "dropouts": {"count": len(drop_ms), "total_ms": float(sum(drop_ms))},
            "file_corruption": bool(ulog.file_corruption), "parser_reports": printed.lines}
    return from_series(series, what, sig_units, meta, ts, start, stop, source)


def px4_cascade_gains(path: str | os.PathLike, channel: str, axis: str = "x") -> tuple[ChannelGain, dict[str, float]]:
    """``K`` of PX4's position cascade on one axis, from the parameters a ULog file records at its start.

    PX4's multicopter position controller is a position P over a velocity PI whose derivative acts on the
    measured acceleration, so a setpoint offset meets ``K(s) = kpp (kpv + kiv/s)`` on the position channel and
    ``kpv + kiv/s`` on the velocity channel (:mod:`ilcdob.channel_gain`; docs/closed_loop.md, "A cascade's
    position setpoint").

    Parameters
    ----------
    path : str or os.PathLike
        The ``.ulg`` file.
    channel : {"position", "velocity"}
        The setpoint row the learning signal is added to.
    axis : {"x", "y", "z"}
        The axis (x and y share ``MPC_XY_*``).

    Returns
    -------
    (ChannelGain, dict)
        ``K``, and the parameters read (name -> value).

    Raises
    ------
    SignalError
        Not a readable ULog file, or the parameters are missing (a log of PX4 before 1.12, whose velocity gains
        are in thrust units, names ``MPC_XY_VEL_P`` instead: the message says so).
    SpecError
        A bad ``channel`` or ``axis``, or gains that make no cascade.
    """
    if axis not in PX4_CASCADE_PARAMETERS:
        raise SpecError(f"`axis`: got {axis!r}, expected one of {sorted(PX4_CASCADE_PARAMETERS)}")
    source = source_of(path)
    check_file(source)
    ulog, _ = _parse(source, [])
    params = ulog.initial_parameters
    names = PX4_CASCADE_PARAMETERS[axis]
    missing = [n for n in names if n not in params]
    if missing:
        old = [n for n in (m.replace("_ACC", "") for m in missing) if n in params]
        hint = (f"; it has {old}: PX4 before 1.12 states the velocity gains in thrust units, so give "
                "--cascade-gains with them converted (times g over the hover thrust, MPC_THR_HOVER)" if old else "")
        raise SignalError(f"{source}: no parameter {missing} in the log's initial parameters{hint}")
    read = {n: float(f"{float(params[n]):.7g}") for n in names}  # float32 in the log: 0.95, not 0.949999988
    try:
        return ChannelGain.cascade(channel, *read.values()), read
    except SpecError as exc:
        raise SpecError(f"{source}: {', '.join(f'{k} = {v:g}' for k, v in read.items())}: {exc}") from None
