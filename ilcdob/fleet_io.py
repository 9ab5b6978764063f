"""Writing fleet files: specs to TOML text, and adding an identified system to a fleet file.

:func:`fleet_to_toml` writes a whole fleet in the schema of :mod:`ilcdob.fleet` (numbers with
``repr``, so that the file loads back to equal specs); a system may refer to its identified
``model.json`` instead of stating num/den/delay/identification. :func:`add_system` (behind
``ilcdob fleet add``) creates a fleet file or appends one ``[[system]]`` table to it, keeping
the rest of the file (comments included) byte for byte, after validating the whole resulting
fleet (keys, values, model file, stable loops); the file is written atomically, so a refused
system leaves it unchanged. The read, the validation and the write happen under an advisory
lock (:func:`ilcdob.atomic.locked`): two ``fleet add`` into one file at the same time both
land, one after the other.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import locked, make_folders, remove_folders, write_text_atomic
from .errors import FleetError
from .fleet import MODEL_FILE_KEY, Fleet, fleet_from_dict, read_fleet_file
from .identified import load_model
from .inputs import parse_toml
from .specs import DOBSpec, LimitSpec, NoiseSpec, PIDSpec, SensorSpec, SystemSpec, UncertaintySpec

__all__ = ["fleet_to_toml", "system_table", "system_to_toml", "toml_value", "add_system", "add_channel_system",
           "model_reference"]


def _toml_string(text: str) -> str:
    out = []
    for ch in text:
        code = ord(ch)
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\t":
            out.append(ch)
        elif code < 0x20 or code == 0x7F:
            out.append(f"\\u{code:04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_value(value: Any) -> str:
    """``value`` as a TOML value: bool, int, float (``repr``; ``nan``/``inf``), str, list, inline table.

    Parameters
    ----------
    value : bool, int, float, str, sequence or mapping
        NumPy scalars are accepted; lists and mappings are written recursively (a mapping as an
        inline table).

    Returns
    -------
    str
        The TOML text of the value.

    Raises
    ------
    FleetError
        A value of another type (the message names it).
    """
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        value = float(value)  # repr of a NumPy float is "np.float64(...)"
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise FleetError(f"cannot write {type(value).__name__} {value!r} to TOML; expected bool, int, float, str, "
                     "list or table")


def _plant_table(plant: Any, with_delay: bool) -> dict[str, Any]:
    table: dict[str, Any] = {"num": list(plant.num), "den": list(plant.den)}
    if with_delay:
        table["delay"] = plant.delay
    return table


def system_table(spec: SystemSpec, model_file: str | None = None) -> dict[str, Any]:
    """One ``[[system]]`` table of ``spec`` in the fleet schema (see :mod:`ilcdob.fleet`).

    Parameters
    ----------
    spec : SystemSpec
    model_file : str, optional
        Path (as it should appear in the file) of the ``model.json`` the nominal model was
        identified in: it then stands for the plant (``plant = { model = ... }``) or, when the
        system has a separate ``model``, for that (``model = { model = ... }``), replacing the
        polynomials, delay and ``identification`` it defines.

    Returns
    -------
    dict
        Keys in file order; optional tables only when they differ from their defaults.
    """
    table: dict[str, Any] = {"name": spec.name}
    file_is_model = model_file is not None and spec.model is not None
    if model_file is not None and not file_is_model:
        table["plant"] = {MODEL_FILE_KEY: model_file}
    else:
        table["plant"] = _plant_table(spec.plant, with_delay=False)
        table["delay"] = spec.plant.delay
    if spec.model is not None:
        table["model"] = {MODEL_FILE_KEY: model_file} if file_is_model else _plant_table(spec.model, with_delay=True)
    c, q = spec.controller, spec.dob
    table["controller"] = {"kp": c.kp, "ki": c.ki, "kd": c.kd, "derivative_filter": c.derivative_filter}
    if not c.acceleration_feedforward:
        table["controller"]["acceleration_feedforward"] = False
    table["dob"] = {"q_order": q.q_order, "q_time_constant": q.q_time_constant}
    if spec.noise != NoiseSpec():
        n = spec.noise
        table["noise"] = {"amplitude": n.amplitude, "frequency": n.frequency, "phase": n.phase}
    if spec.identification is not None and model_file is None:
        i = spec.identification
        table["identification"] = {
            "poles": i.poles, "zeros": i.zeros, "integrators": i.integrators, "parameters": list(i.parameters),
            "covariance": [list(row) for row in i.covariance], "delay_estimated": i.delay_estimated,
            "fit_estimation": i.fit_estimation, "fit_validation": i.fit_validation, "source": i.source}
    if spec.uncertainty is not None:
        table["uncertainty"] = {"bound": spec.uncertainty.bound}
    return {**table, **_limit_tables(spec.limits, spec.sensor)}


def _limit_tables(limits: LimitSpec | None, sensor: SensorSpec | None) -> dict[str, Any]:
    """The ``limits`` and ``sensor`` tables of a system (each only when given)."""
    table: dict[str, Any] = {}
    if limits is not None:
        table["limits"] = {k: getattr(limits, k) for k in ("tilt", "thrust_to_weight", "acceleration")
                           if getattr(limits, k) is not None}
    if sensor is not None:
        table["sensor"] = {"noise_std": sensor.noise_std}
    return table


def _table_to_toml(table: Mapping[str, Any]) -> str:
    return "[[system]]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in table.items())


def system_to_toml(spec: SystemSpec, model_file: str | None = None) -> str:
    """The ``[[system]]`` block of ``spec`` (see :func:`system_table`), ending in a newline.

    Parameters
    ----------
    spec : SystemSpec
        The system.
    model_file : str, optional
        Its ``model.json``, as it should appear in the file (see :func:`system_table`).

    Returns
    -------
    str
        The block's TOML text.
    """
    return _table_to_toml(system_table(spec, model_file))


def fleet_to_toml(sample_time: float, systems: Sequence[SystemSpec], *,
                  model_files: Mapping[str, str] | None = None, description: str | None = None,
                  header: str = "") -> str:
    """A fleet file: ``sample_time``, optional ``description``, one ``[[system]]`` per system.

    Parameters
    ----------
    sample_time : float
        s.
    systems : sequence of SystemSpec
    model_files : mapping of str to str, optional
        System name -> path of its ``model.json`` as it should appear in the file (see
        :func:`system_table`); relative paths are relative to the fleet file's folder.
    description : str, optional
    header : str
        Comment lines put first (each is prefixed with ``# `` unless it already starts with ``#``).

    Returns
    -------
    str
        TOML that :func:`ilcdob.fleet.load_fleet` loads back to equal specs.
    """
    model_files = dict(model_files or {})
    unknown = sorted(set(model_files) - {s.name for s in systems})
    if unknown:
        raise FleetError(f"`model_files`: no system named {unknown}; the systems are {[s.name for s in systems]}")
    lines = [ln if ln.startswith("#") else f"# {ln}" for ln in header.splitlines()]
    if description is not None:
        lines.append(f"description = {toml_value(description)}")
    lines.append(f"sample_time = {toml_value(float(sample_time))}   # s")
    blocks = [system_to_toml(s, model_files.get(s.name)) for s in systems]
    return "\n".join(lines) + "\n\n" + "\n".join(blocks)


def model_reference(model: str | Path, fleet_path: str | Path) -> str:
    """How a fleet file at ``fleet_path`` refers to ``model``: relative to its folder, with ``/``.

    Parameters
    ----------
    model : str or Path
        The model file; relative to the working directory when relative.
    fleet_path : str or Path
        The fleet file; relative to the working directory when relative.

    Returns
    -------
    str
        The path of ``model`` relative to the fleet file's folder, with ``/`` separators, or
        the absolute path when no relative one exists (another drive on Windows).
    """
    target = os.path.abspath(model)
    folder = os.path.dirname(os.path.abspath(fleet_path))
    try:
        return Path(os.path.relpath(target, folder)).as_posix()
    except ValueError:
        return Path(target).as_posix()


def add_system(path: str | Path, name: str, model: str | Path, controller: PIDSpec, dob: DOBSpec, *,
               sample_time: float | None = None, noise: NoiseSpec | None = None,
               uncertainty: UncertaintySpec | None = None, limits: LimitSpec | None = None,
               sensor: SensorSpec | None = None) -> Fleet:
    """Add a system flying an identified model to a fleet file, creating the file if needed.

    The system's plant is ``plant = { model = "<model, relative to the fleet file>" }``: its
    num/den/delay and its identification (the Delta set's covariance) come from the model
    file. The whole resulting fleet is validated (keys, values, model file, stable loops)
    before anything is written; the file is then written atomically. An existing file keeps
    its text: the new ``[[system]]`` table is appended. The file is read, validated and
    written under an exclusive lock on its folder (:func:`ilcdob.atomic.locked`), so
    concurrent calls on one file are applied one after the other and none is lost; a folder
    created for a new file is removed again when the system is refused.

    Parameters
    ----------
    path : str or pathlib.Path
        The fleet TOML file (created when it does not exist). A symbolic link is followed: the
        file it points to is edited (the link stays), and the model's path is written relative
        to that file's folder.
    name : str
        Name of the new system; must not be in the fleet yet.
    model : str or pathlib.Path
        The ``model.json`` of ``ilcdob identify`` (relative to the working directory).
    controller : PIDSpec
    dob : DOBSpec
    sample_time : float, optional
        s. A new file gets this sample time, or, when None, the model's (``sample_time`` of
        the model file, rounded to 12 significant digits: one measured from time stamps
        carries float roundoff). For an existing file it must equal the file's, if given.
    noise : NoiseSpec, optional
        The system's own process noise (default: none).
    uncertainty : UncertaintySpec, optional
        A stated model-error bound, used ahead of the covariance for the Delta set.
    limits : LimitSpec, optional
        The vehicle's acceleration limit (a learning signal beyond it is clipped or refused).
    sensor : SensorSpec, optional
        Its position sensor's white noise (sets the learning band without a trial).

    Returns
    -------
    Fleet
        The validated fleet as written.

    Raises
    ------
    FleetError
        The name exists already, the sample time conflicts, the fleet file or the model file
        is invalid, or a loop of the resulting fleet is unstable; nothing is written then.
    ModelFileError
        The model file cannot be read or is malformed.
    ilcdob.atomic.LockTimeoutError
        Another process kept the fleet file's folder locked for
        :data:`ilcdob.atomic.LOCK_TIMEOUT_S`.
    """
    path = _fleet_target(path, name)
    identified = load_model(model)
    table: dict[str, Any] = {"name": name, "plant": {MODEL_FILE_KEY: model_reference(model, path)},
                             "controller": {"kp": controller.kp, "ki": controller.ki, "kd": controller.kd,
                                            "derivative_filter": controller.derivative_filter},
                             "dob": {"q_order": dob.q_order, "q_time_constant": dob.q_time_constant}}
    if not controller.acceleration_feedforward:
        table["controller"]["acceleration_feedforward"] = False
    if noise is not None and noise != NoiseSpec():
        table["noise"] = {"amplitude": noise.amplitude, "frequency": noise.frequency, "phase": noise.phase}
    if uncertainty is not None:
        table["uncertainty"] = {"bound": uncertainty.bound}
    return _add_table(path, {**table, **_limit_tables(limits, sensor)}, identified.sample_time, sample_time)


def add_channel_system(path: str | Path, name: str, model: str | Path, channel: str, *,
                       channel_gain: float | dict[str, Any] | None = None, airframe: str | Path | None = None,
                       dob: DOBSpec | None = None, sample_time: float | None = None,
                       reference_map: str | Path | None = None, limits: LimitSpec | None = None,
                       sensor: SensorSpec | None = None) -> Fleet:
    """Add a vehicle on its own controller to a fleet file (:mod:`ilcdob.fleet`'s ``channel`` systems), creating
    the file if needed; validated, locked and written as :func:`add_system` does.

    Parameters
    ----------
    path : str or pathlib.Path
        The fleet TOML file (created when it does not exist; a symbolic link is followed).
    name : str
        Name of the new system; must not be in the fleet yet.
    model : str or pathlib.Path
        The ``model.json`` of ``ilcdob identify`` fitted from the channel (input) to the position (output) with
        the vehicle's loop closed: its ``channel_map``.
    channel : {"position", "velocity", "acceleration"}
        Where the learning signal enters.
    channel_gain : float or dict, optional
        ``K``, m/s^2 per channel unit (required off the acceleration channel: the controller's kp or kd), or a
        ``channel_gain`` table of :mod:`ilcdob.fleet` (a cascade's gains, or ``num``/``den``).
    airframe : str or pathlib.Path, optional
        The ``model.json`` of the airframe (commanded acceleration -> position).
    dob : DOBSpec, optional
        The add-on DOB the vehicle flies (its channel map identified with it flying).
    sample_time : float, optional
        As :func:`add_system`.
    reference_map : str or pathlib.Path, optional
        The ``model.json`` of the reference map (reference -> position as the flight stack flies it).
    limits, sensor : LimitSpec or SensorSpec, optional
        As :func:`add_system`.

    Returns
    -------
    Fleet
        The validated fleet as written.

    Raises
    ------
    FleetError
        As :func:`add_system`; a bad channel or gain; nothing is written then.
    ModelFileError
        A model file cannot be read or is malformed.
    ilcdob.atomic.LockTimeoutError
        As :func:`add_system`.
    """
    path = _fleet_target(path, name)
    identified = load_model(model)
    table: dict[str, Any] = {"name": name, "channel": channel,
                             "channel_map": {MODEL_FILE_KEY: model_reference(model, path)}}
    if channel_gain is not None:
        table["channel_gain"] = channel_gain
    for key, file in (("airframe", airframe), ("reference_map", reference_map)):
        if file is not None:
            load_model(file)
            table[key] = {MODEL_FILE_KEY: model_reference(file, path)}
    if dob is not None:
        table["dob"] = {"q_order": dob.q_order, "q_time_constant": dob.q_time_constant}
    return _add_table(path, {**table, **_limit_tables(limits, sensor)}, identified.sample_time, sample_time)


def _fleet_target(path: str | Path, name: object) -> Path:
    """The fleet file a system is added to (a symbolic link followed: the file it points to is edited, the link
    stays, and model paths are relative to that file), after checking the new system's ``name`` is given."""
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()
    if not isinstance(name, str) or not name.strip():
        raise FleetError(f"{path}: `name`: got {name!r}, expected a non-empty string")
    return path


def _add_table(path: Path, table: dict[str, Any], model_ts: float, sample_time: float | None) -> Fleet:
    """Append the ``[[system]]`` ``table`` to the fleet file under its folder's lock (the folder made for a new file
    removed again when the system is refused)."""
    block = _table_to_toml(table)
    created = make_folders(path.absolute().parent)  # the lock is on the folder: it must exist
    try:
        with locked(path):  # read, validate and write as one step: a concurrent add waits for this one
            return _append(path, table["name"], block, model_ts, sample_time)
    except BaseException:
        remove_folders(created)
        raise


def _warn_rates(path: Path, name: str, model_ts: float, fleet_ts: float) -> None:
    """Warn where a model was identified at another sample time than the fleet flies."""
    if abs(model_ts - fleet_ts) > 1e-9 * abs(fleet_ts):
        warnings.warn(f"{path}: system {name!r}: its model was identified at a sample time of {model_ts:.6g} s, the "
                      f"fleet flies at {fleet_ts:g} s; the model's continuous form is sampled at the fleet's rate, "
                      "which holds where its log resolved the band the loop needs: if it did not, identify it from a "
                      f"log at the fleet's rate (identify --resample {fleet_ts:g})", UserWarning, stacklevel=5)


def _append(path: Path, name: str, block: str, model_ts: float, sample_time: float | None) -> Fleet:
    """Append ``block`` to the fleet file (created when missing), validated, written atomically."""
    if path.exists():
        text, data = read_fleet_file(path)
        existing = data.get("system", [])
        names = [t.get("name") for t in existing if isinstance(t, dict)] if isinstance(existing, list) else []
        if name in names:
            raise FleetError(f"{path}: system {name!r} exists already (systems: {names}); choose another name or "
                             "remove its [[system]] table first")
        file_ts = data.get("sample_time")
        if sample_time is not None and file_ts != sample_time:
            raise FleetError(f"{path}: `sample_time`: got {sample_time!r}, but the fleet's sample_time is "
                             f"{file_ts!r} s; a system is added at the fleet's sample time (omit it)")
        if isinstance(file_ts, (int, float)):
            _warn_rates(path, name, model_ts, file_ts)
        new_text = text + ("" if text.endswith("\n") or not text else "\n") + "\n" + block
    else:
        # a sample time measured from time stamps carries float roundoff (0.019999999999999997)
        ts = float(f"{model_ts:.12g}") if sample_time is None else sample_time
        _warn_rates(path, name, model_ts, ts)
        new_text = (f"# Fleet file (schema: ilcdob.fleet); systems added with `ilcdob fleet add`\n"
                    f"sample_time = {toml_value(float(ts))}   # s\n\n" + block)
    data = parse_toml(new_text, path, "fleet file", error=FleetError,
                      hint=f"appending system {name!r} gave this (the file ends inside a multi-line construct?); "
                           "fix the end of the file")
    fleet = fleet_from_dict(data, str(path), base_dir=path.parent)
    write_text_atomic(path, new_text)
    return fleet
