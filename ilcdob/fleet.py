"""Fleets: several systems flying the same task, loaded from TOML.

Schema (one ``[[system]]`` table per vehicle; units in comments)::

    sample_time = 0.02                      # s, 1e-4 to 1 (SAMPLE_TIME_RANGE)
    [[system]]
    name = "UAV1"
    plant = { num = [1.0], den = [0.1, 1.0, 0.0, 0.0] }  # continuous, s-polynomials, highest power first
    delay = 0.0                             # s, plant input delay (optional, default 0)
    controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
    # C(s) = kp + ki/s + kd*s/(derivative_filter*s + 1); optional acceleration_feedforward = true
    dob = { q_order = 3, q_time_constant = 0.15 }
    # optional:
    model = { num = [...], den = [...], delay = 0.0 }   # P_hat when it differs from the plant
    noise = { amplitude = 0.05, frequency = 2.0, phase = 0.0 }  # m/s^2, Hz, rad
    identification = { poles = 3, zeros = 0, integrators = 2, parameters = [...],
                       covariance = [[...]], fit_estimation = 98.0, fit_validation = 97.5,
                       source = "..." }   # written by `ilcdob identify-fleet`
    uncertainty = { bound = 0.2 }   # |Delta(jw)| <= 0.2: the Delta set, ahead of the identification
    limits = { tilt = 35.0 }        # deg; or thrust_to_weight = 2.0, or acceleration = 6.0 (m/s^2):
                                    # bounds the learning signal (the smallest stated bound counts)
    sensor = { noise_std = 0.0005 } # m, white position-sensor noise: sets the learning band without a trial

An identified plant can instead come straight from the ``model.json`` of ``ilcdob identify``
(path relative to the fleet file's folder, or absolute; see :mod:`ilcdob.identified`)::

    [[system]]
    name = "UAV4"
    plant = { model = "uav4.json" }         # num, den and delay from the file
    controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
    dob = { q_order = 3, q_time_constant = 0.15 }

The file's structure, parameters, covariance, fits and ``delay_estimated`` become the
system's ``identification``, so its Delta set is the one of the covariance, as for fleets
written by ``ilcdob identify-fleet``. ``model = { model = "x.json" }`` takes the nominal model
``P_hat`` from a file likewise; the identification is always that of the nominal model's file
(``model`` when given, else ``plant``), and a system with a model file for its nominal model
may not also state ``identification``; a plant from a file may not also state ``delay``.
``ilcdob fleet add`` (:func:`ilcdob.fleet_io.add_system`) appends such systems to a fleet file.

Three axes. The tables above describe the x axis (the paper's). A system flown on y or z adds
per-axis sections with the same keys (no ``name``); the axis's ``plant`` is required, the
plant's companions (``delay``, ``model``, ``identification``, ``uncertainty``) belong to the plant
they are given with, and ``controller``, ``dob``, ``noise``, ``limits`` and ``sensor`` default to
the x axis's::

    [[system]]
    name = "UAV1"
    plant = { model = "uav1_x.json" }
    controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
    dob = { q_order = 3, q_time_constant = 0.15 }
    [system.z]
    plant = { model = "uav1_z.json" }
    controller = { kp = 4.0, ki = 0.4, kd = 2.8, derivative_filter = 0.05 }

``load_fleet(path, axis="z")`` (``--axis z`` on the command line) is the fleet of that axis,
each axis learned independently; every system then needs a section for it.

A vehicle that flies its own controller (PX4's, ArduPilot's, a Crazyflie's, rotorpy's SE3) is a
system with ``channel`` (docs/closed_loop.md): it is described by its identified closed-loop map from
the learning channel to the position, not by plant, PID and DOB::

    [[system]]
    name = "lab-quad"
    channel = "acceleration"               # or "position" (setpoint offset, m), "velocity" (feed-forward, m/s)
    channel_map = { model = "lab-quad_channel.json" }   # or num/den (+ delay): channel unit -> m, stable
    channel_gain = 1.0                     # K, m/s^2 per channel unit: 1 on acceleration (default there),
                                           # the controller's kp on position, its kd on velocity (required);
                                           # a cascade's: { position_p = 0.95, velocity_p = 1.8, velocity_i = 0.4 }
                                           # (PX4's MPC_XY_P, MPC_XY_VEL_P_ACC, MPC_XY_VEL_I_ACC), or any
                                           # K(s) as { num = [...], den = [...] } (ilcdob.channel_gain)
    airframe = { model = "lab-quad_airframe.json" }      # optional: commanded acceleration -> position,
                                           # for --disturbance airframe/wind and the add-on DOB
    dob = { q_order = 3, q_time_constant = 0.15 }        # optional: the add-on DOB it flies
    reference_map = { model = "lab-quad_reference.json" } # optional: reference -> position, for the
                                           # exact-reference law (default on position: channel_map)
    limits = { acceleration = 6.0 }        # optional, as above; sensor too

The channel map's model file gives its ``identification`` (its Delta set, for ``check``). Per-axis
sections work as for the other systems, with ``channel_map`` required and ``delay``,
``identification``, ``airframe``, ``channel_gain`` and ``reference_map`` bound to it. Such systems and
ilcdob's own loop mix in one fleet; ``ilcdob design`` (the closed form, the robust SOCP or robust-set;
the paper's or the exact-reference law), ``check`` and ``learn`` serve them, and the commands that simulate
ilcdob's loop refuse them (:meth:`Fleet.require_paper_loops`).

A system's ``name`` follows one rule (:func:`ilcdob.names.check_name`): 1 to 64 ASCII
letters, digits, spaces and ``_ - . +``, starting with a letter or a digit and not ending
with a space or ``.``; names end up in C symbols, file names and reports, and are data there.

Every system's loops are built (and checked for stability) when the fleet is loaded. Any
problem raises :class:`~ilcdob.errors.FleetError` naming the file, the system and the key.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any, Sequence

from .channel_gain import ChannelGain, as_channel_gain
from .channel_loop import ChannelLoop, ChannelSystemSpec, check_channel
from .errors import FleetError, ModelFileError, SpecError, UnstableLoopError
from .identified import IdentifiedModel, load_model
from .inputs import parse_toml, read_text
from .loop import LoopSystem, build_loop
from .names import check_name, quoted
from .specs import (DOBSpec, IdentificationSpec, LimitSpec, NoiseSpec, PIDSpec, PlantSpec, SensorSpec, SystemSpec,
                    UncertaintySpec)

__all__ = ["AXES", "Fleet", "load_fleet", "axis_table", "read_fleet_file", "default_fleet", "DEFAULT_FLEET_PATH",
           "fleet_from_dict", "fleet_from_systems", "MODEL_FILE_KEY", "SAMPLE_TIME_RANGE"]

DEFAULT_FLEET_PATH = Path(str(resources.files("ilcdob") / "data" / "default_fleet.toml"))

_TOP_KEYS = {"sample_time": True, "system": True, "description": False}
#: Sample times a fleet may have, s: ten times beyond what ilcdob is built and tested for (1 ms to 50 ms)
#: on the fast side (a 10 kHz outer loop: a 60 s scenario is 600,000 samples a flight), 1 s on the slow
#: one (a position loop slower than 1 Hz holds no quadrotor; the scenarios' disturbances, 0.94 and
#: 1.41 rad/s, come within a factor of 2.2 of its Nyquist frequency). Outside, the value is in the wrong
#: unit (20 meaning ms), or would make every trial enormous (1e-7 s: 600 million samples a flight).
SAMPLE_TIME_RANGE = (1e-4, 1.0)
_SYSTEM_KEYS = {"name": True, "plant": True, "controller": True, "dob": True,
                "delay": False, "model": False, "noise": False, "identification": False, "uncertainty": False,
                "limits": False, "sensor": False, "y": False, "z": False}
#: Keys of a vehicle on its own controller (a system with ``channel``; module docstring).
_CHANNEL_SYSTEM_KEYS = {"name": True, "channel": True, "channel_map": True, "channel_gain": False, "delay": False,
                        "airframe": False, "dob": False, "identification": False, "limits": False, "sensor": False,
                        "reference_map": False, "y": False, "z": False}
#: Keys bound to a channel map: an axis section that gives its own map does not inherit them from x.
_CHANNEL_MAP_KEYS = ("channel_map", "delay", "identification", "airframe", "channel_gain", "reference_map")
#: The axes a fleet file can describe; x is the top level of each system (module docstring).
AXES = ("x", "y", "z")
#: Keys bound to a plant: an axis section that gives its own plant does not inherit them from x.
_PLANT_KEYS = ("plant", "delay", "model", "identification", "uncertainty")
_TABLE_KEYS = {
    "plant": {"num": True, "den": True},
    "model": {"num": True, "den": True, "delay": False},
    "controller": {"kp": True, "ki": True, "kd": True, "derivative_filter": True,
                   "acceleration_feedforward": False},
    "dob": {"q_order": True, "q_time_constant": True},
    "noise": {"amplitude": False, "frequency": False, "phase": False},
    "identification": {"poles": True, "zeros": True, "integrators": True, "parameters": True,
                       "covariance": True, "delay_estimated": False, "fit_estimation": False,
                       "fit_validation": False, "source": False},
    "uncertainty": {"bound": True},
    "limits": {"tilt": False, "thrust_to_weight": False, "acceleration": False},
    "sensor": {"noise_std": True},
    "channel_map": {"num": True, "den": True},
    "airframe": {"num": True, "den": True, "delay": False},
    "reference_map": {"num": True, "den": True, "delay": False},
}
#: Key of a ``plant``/``model`` table naming a model file instead of giving num/den.
MODEL_FILE_KEY = "model"
_SPEC_CLASS = {"plant": PlantSpec, "model": PlantSpec, "controller": PIDSpec, "dob": DOBSpec,
               "noise": NoiseSpec, "identification": IdentificationSpec, "uncertainty": UncertaintySpec,
               "limits": LimitSpec, "sensor": SensorSpec, "channel_map": PlantSpec, "airframe": PlantSpec,
               "reference_map": PlantSpec}


@dataclass(frozen=True)
class Fleet:
    """Systems sharing a sample time, in file order.

    Attributes
    ----------
    sample_time : float
        s.
    systems : tuple of SystemSpec or ChannelSystemSpec
        ilcdob's PID + DOB loop, or a vehicle on its own controller (module docstring).
    loops : tuple of LoopSystem or ChannelLoop
        Built, stability-checked loops, one per system.
    source : str
        Where the fleet came from (file path), for messages.
    axis : {"x", "y", "z"}
        The axis the systems describe (x: the paper's; module docstring).
    """

    sample_time: float
    systems: tuple[SystemSpec | ChannelSystemSpec, ...]
    loops: tuple[LoopSystem | ChannelLoop, ...]
    source: str = "<memory>"
    axis: str = "x"

    def __repr__(self) -> str:
        return (f"<Fleet {', '.join(self.names)}; sample time {self.sample_time:g} s; from {self.source}"
                + ("" if self.axis == "x" else f"; axis {self.axis}") + ">")

    def _repr_html_(self) -> str:
        from .display import html_table

        rows = []
        for s in self.systems:
            if isinstance(s, ChannelSystemSpec):
                p = s.channel_map
                rows.append([s.name, f"{s.channel} channel: {list(p.num)} / {list(p.den)}", p.delay,
                             f"own controller, {as_channel_gain(s.channel_gain).describe()}",
                             "-" if s.dob is None else f"{s.dob.q_order}, {s.dob.q_time_constant:g} s",
                             "identified" if s.identification else "-"])
                continue
            p, c = s.nominal_plant, s.controller
            rows.append([s.name, f"{list(p.num)} / {list(p.den)}", p.delay, f"{c.kp:g} / {c.ki:g} / {c.kd:g}",
                         f"{s.dob.q_order}, {s.dob.q_time_constant:g} s",
                         "identified" if s.identification else ("bound" if s.uncertainty else "-")])
        return html_table(f"Fleet from {self.source}, sample time {self.sample_time:g} s",
                          ["system", "model num / den", "delay (s)", "kp / ki / kd", "Q order, time constant",
                           "uncertainty"], rows)

    @property
    def names(self) -> list[str]:
        """Names of the systems, in file order."""
        return [s.name for s in self.systems]

    @property
    def own_controller(self) -> list[str]:
        """Names of the systems flying their own controller (``channel`` systems), in file order."""
        return [s.name for s in self.systems if isinstance(s, ChannelSystemSpec)]

    def require_paper_loops(self, what: str) -> None:
        """Refuse a fleet with a vehicle on its own controller for ``what``, which needs ilcdob's PID + DOB on all.

        Parameters
        ----------
        what : str
            The command or function, for the message.

        Raises
        ------
        FleetError
            Some system is a ``channel`` system (the message names them and what serves them).
        """
        own = self.own_controller
        if own:
            raise FleetError(f"{self.source}: {what} needs ilcdob's PID + DOB loop on every system, and {own} fly "
                             "their own controller (`channel` systems): `ilcdob design`, `check` and `learn` serve "
                             "them; docs/closed_loop.md")

    def loop(self, name: str) -> LoopSystem | ChannelLoop:
        """The loop of one system.

        Parameters
        ----------
        name : str
            The system's name.

        Returns
        -------
        LoopSystem or ChannelLoop
            Its built, stability-checked loop.

        Raises
        ------
        FleetError
            No system of that name (the message lists the names).
        """
        for lp in self.loops:
            if lp.name == name:
                return lp
        raise FleetError(f"{self.source}: no system named {name!r}; the fleet has {self.names}")


def _check_keys(where: str, table: Any, spec: dict[str, bool], alternative: str = "") -> None:
    if not isinstance(table, dict):
        raise FleetError(f"{where}: expected a table, got {table!r}{alternative}")
    unknown = sorted(set(table) - set(spec))
    if unknown:
        raise FleetError(f"{where}: unknown key(s) {unknown}; valid keys are {sorted(spec)}{alternative}")
    missing = sorted(k for k, req in spec.items() if req and k not in table)
    if missing:
        raise FleetError(f"{where}: missing key(s) {missing}{alternative}")


def _model_file(label: str, key: str, sub: dict[str, Any], base_dir: Path | None) -> IdentifiedModel:
    """The model file named by ``sub[MODEL_FILE_KEY]`` of table ``key``, loaded and checked."""
    value = sub[MODEL_FILE_KEY]
    others = [k for k in sub if k != MODEL_FILE_KEY]
    if others:
        listed = ", ".join(f"`{k}` = {sub[k]!r}" for k in others)
        raise FleetError(f"{label}, key `{key}`: `{MODEL_FILE_KEY}` = {value!r} cannot be combined with {listed}; "
                         f"give either a model file ({key} = {{ {MODEL_FILE_KEY} = \"uav4.json\" }}) or the "
                         "polynomials")
    if not isinstance(value, str) or not value.strip():
        raise FleetError(f"{label}, key `{key}.{MODEL_FILE_KEY}`: got {value!r}, expected the path of a model.json "
                         "(relative to the fleet file's folder, or absolute)")
    path = Path(value)
    if not path.is_absolute() and base_dir is not None:
        path = Path(os.path.normpath(base_dir / path))  # lexical, like the relative path add_system stores
    try:
        return load_model(path)
    except ModelFileError as exc:
        raise FleetError(f"{label}, key `{key}.{MODEL_FILE_KEY}` = {value!r}: {exc}") from exc


def _system_from_table(src: str, idx: int, table: Any,
                       base_dir: Path | None = None) -> SystemSpec | ChannelSystemSpec:
    label = f"{src}: system #{idx + 1}"
    if isinstance(table, dict) and isinstance(table.get("name"), str):
        label = f"{src}: system {quoted(table['name'])}"
    own = isinstance(table, dict) and "channel" in table
    _check_keys(label, table, _CHANNEL_SYSTEM_KEYS if own else _SYSTEM_KEYS, _KIND_HINT if own else "")
    try:
        check_name(table["name"])
    except SpecError as exc:  # before anything else of the system is read: a name is never a path or code
        raise FleetError(f"{src}: system #{idx + 1}: {exc}") from exc
    map_key = "channel_map" if own else "plant"
    files = {key: _model_file(label, key, table[key], base_dir)
             for key in (("channel_map", "airframe", "reference_map") if own else ("plant", "model"))
             if isinstance(table.get(key), dict) and MODEL_FILE_KEY in table[key]}
    if map_key in files and "delay" in table:
        raise FleetError(f"{label}, key `delay`: got {table['delay']!r}, but the {map_key.replace('_', ' ')}'s delay "
                         f"comes from {table[map_key][MODEL_FILE_KEY]!r} (delay = {files[map_key].delay:g} s); "
                         "remove `delay`")
    nominal_key = map_key if own or "model" not in table else "model"
    if nominal_key in files and "identification" in table:
        raise FleetError(f"{label}, key `identification`: the identification comes from the model file "
                         f"{table[nominal_key][MODEL_FILE_KEY]!r} of `{nominal_key}`; remove the "
                         "`identification` table")
    parts = _spec_parts(label, table, files, map_key)
    if nominal_key in files:
        parts["identification"] = files[nominal_key].identification_spec(source=table[nominal_key][MODEL_FILE_KEY])
    try:
        if own:
            return ChannelSystemSpec(name=table["name"], channel=table["channel"],
                                     channel_gain=_channel_gain(label, table), **parts)
        return SystemSpec(name=table["name"], **parts)
    except SpecError as exc:  # its message starts with the system's name already
        raise FleetError(f"{src}: {exc}" if str(exc).startswith("system ") else f"{label}: {exc}") from exc


#: Appended to a key error of a vehicle on its own controller: what such a system is.
_KIND_HINT = (" (a system with `channel` flies its own controller and is described by its identified channel map; "
              "a system without it flies ilcdob's PID + DOB: plant, controller, dob)")


def _spec_parts(label: str, table: dict[str, Any], files: dict[str, IdentifiedModel], map_key: str) -> dict[str, Any]:
    """The spec of every table key of a system (:data:`_TABLE_KEYS`), model files' plants included."""
    parts: dict[str, Any] = {}
    for key, keys in _TABLE_KEYS.items():
        if key not in table:
            continue
        if key in files:
            parts[key] = files[key].plant_spec()
            continue
        plant_like = key in ("plant", "model", "channel_map", "airframe", "reference_map")
        alternative = f", or only `{MODEL_FILE_KEY}` (a model.json)" if plant_like else ""
        _check_keys(f"{label}, key `{key}`", table[key], keys, alternative)
        kwargs = dict(table[key])
        if key == map_key:
            kwargs["delay"] = table.get("delay", 0.0)
        try:
            parts[key] = _SPEC_CLASS[key](**kwargs)
        except (SpecError, TypeError) as exc:
            raise FleetError(f"{label}, key `{key}`: {exc}") from exc
    return parts


#: Keys of a cascade's ``channel_gain`` table (:meth:`ilcdob.channel_gain.ChannelGain.cascade`).
_CASCADE_KEYS = {"position_p": True, "velocity_p": True, "velocity_i": False}


def _channel_gain(label: str, table: dict[str, Any]) -> float | ChannelGain:
    """``channel_gain`` of a vehicle on its own controller: required off the acceleration channel; a number, a
    cascade's gains or a transfer function (module docstring)."""
    try:
        check_channel(table["channel"])
    except SpecError as exc:
        raise FleetError(f"{label}: {exc}") from exc
    gain = table.get("channel_gain", 1.0 if table["channel"] == "acceleration" else None)
    if gain is None:
        raise FleetError(f"{label}: missing key `channel_gain` on the {table['channel']!r} channel: the "
                         "acceleration (m/s^2) the vehicle's controller commands per unit of channel signal (its "
                         "position gain kp on the position channel, its velocity gain kd on the velocity channel; "
                         "docs/closed_loop.md)")
    what = f"{label}, key `channel_gain`"
    try:
        if isinstance(gain, dict) and "position_p" in gain:
            _check_keys(what, gain, _CASCADE_KEYS)
            return ChannelGain.cascade(table["channel"], gain["position_p"], gain["velocity_p"],
                                       gain.get("velocity_i", 0.0))
        if isinstance(gain, dict):
            return as_channel_gain(gain)
    except SpecError as exc:
        raise FleetError(f"{what}: {exc}") from exc
    if isinstance(gain, bool) or not isinstance(gain, (int, float)):
        raise FleetError(f"{what}: got {gain!r}, expected a number > 0, a cascade's gains {{position_p, velocity_p, "
                         "velocity_i}, or a transfer function {num, den}")
    return float(gain)


def axis_table(src: str, idx: int, table: Any, axis: str) -> Any:
    """One ``[[system]]`` table as the flat table of one axis (module docstring): x is the table without its
    axis sections; y or z is the x table with the plant-bound keys replaced by the axis section's and the
    other keys it states overriding.

    Parameters
    ----------
    src : str
        The fleet's source, for messages.
    idx : int
        The system's position in the file (0-based), for messages.
    table : dict
        The parsed ``[[system]]`` table.
    axis : {"x", "y", "z"}
        The axis.

    Returns
    -------
    dict
        A table for a single axis (no ``y``/``z`` keys); ``table`` itself when it is not a dict.

    Raises
    ------
    FleetError
        An unknown axis, a system without the axis's section, or a section that is not a table, names a
        system or lacks its plant.
    """
    if axis not in AXES:
        raise FleetError(f"{src}: axis {axis!r}: expected one of {list(AXES)}")
    if not isinstance(table, dict):
        return table
    flat = {k: v for k, v in table.items() if k not in AXES}
    if axis == "x":
        return flat
    label = f"{src}: system {quoted(table.get('name', f'#{idx + 1}'))}"
    section = table.get(axis)
    if section is None:
        raise FleetError(f"{label}: no [system.{axis}] section; the {axis} axis needs its own plant (and "
                         f"optionally controller, dob, limits), or fly the x axis")
    if not isinstance(section, dict):
        raise FleetError(f"{label}, key `{axis}`: got {section!r}, expected a table of the axis's plant, "
                         "controller and DOB")
    for key, what in (("name", "the system's name belongs to the [[system]] table"),
                      ("y", "axis sections do not nest"), ("z", "axis sections do not nest")):
        if key in section:
            raise FleetError(f"{label}, [system.{axis}] key `{key}`: {what}")
    own = "channel" in flat or "channel" in section
    map_key, bound = ("channel_map", _CHANNEL_MAP_KEYS) if own else ("plant", _PLANT_KEYS)
    if map_key not in section:
        raise FleetError(f"{label}, [system.{axis}]: missing key `{map_key}` (each axis has its own "
                         f"{'identified channel map' if own else 'plant'})")
    return {**{k: v for k, v in flat.items() if k not in bound}, **section}


def _check_sample_time(source: str, ts: Any) -> None:
    lo, hi = SAMPLE_TIME_RANGE
    if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not lo <= ts <= hi:
        raise FleetError(f"{source}: key `sample_time`: got {ts!r}, expected a sample time of {lo:g} to {hi:g} s "
                         "(ilcdob is built for 0.001 to 0.05 s; check the unit: s)")


def fleet_from_dict(data: dict[str, Any], source: str = "<memory>", base_dir: str | Path | None = None,
                    axis: str = "x") -> Fleet:
    """Validate a parsed fleet table and build its loops (see module docstring).

    Parameters
    ----------
    data : dict
        The parsed TOML.
    source : str
        Where it came from, for messages.
    base_dir : str or pathlib.Path, optional
        Folder that relative model-file paths (``plant = { model = "..." }``) are relative to
        (:func:`load_fleet`: the fleet file's folder; default: the working directory).
    axis : {"x", "y", "z"}
        The axis whose systems are built (:func:`axis_table`).

    Raises
    ------
    FleetError
        See :func:`load_fleet`.
    """
    _check_keys(source, data, _TOP_KEYS)
    ts = data["sample_time"]
    _check_sample_time(source, ts)
    tables = data["system"]
    if not isinstance(tables, list) or not tables:
        raise FleetError(f"{source}: key `system`: expected one or more [[system]] tables")
    base = Path(base_dir) if base_dir is not None else None
    label = source if axis == "x" else f"{source} (axis {axis})"
    systems = [_system_from_table(label, i, axis_table(source, i, t, axis), base) for i, t in enumerate(tables)]
    return replace(fleet_from_systems(systems, float(ts), source), axis=axis)


def fleet_from_systems(systems: Sequence[SystemSpec | ChannelSystemSpec], sample_time: float, source: str = "<memory>") -> Fleet:
    """A fleet from system specs built in Python: names checked, loops built and stability-checked.

    Plants may be python-control systems (``SystemSpec(plant=ct.tf(...), ...)``), or come
    from identified models (:meth:`ilcdob.identified.IdentifiedModel.system_spec`).

    Parameters
    ----------
    systems : sequence of SystemSpec or ChannelSystemSpec
        In learning order (file order).
    sample_time : float
        s (> 0).
    source : str
        Name used in messages.

    Raises
    ------
    FleetError
        No systems, a value that is not a ``SystemSpec``, a duplicated name, an invalid sample
        time or an unstable loop; the message names the system and the key.
    """
    _check_sample_time(source, sample_time)
    systems = list(systems)
    if not systems:
        raise FleetError(f"{source}: key `system`: expected one or more systems, got none")
    for i, spec in enumerate(systems):
        if not isinstance(spec, (SystemSpec, ChannelSystemSpec)):
            raise FleetError(f"{source}: system #{i + 1}: got {type(spec).__name__} {spec!r}, expected a SystemSpec "
                             "or a ChannelSystemSpec")
    ts = float(sample_time)
    names = [s.name for s in systems]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FleetError(f"{source}: key `name`: duplicated system name(s) {dup}")
    loops = []
    for spec in systems:
        own = isinstance(spec, ChannelSystemSpec)
        try:
            lp = spec.loop(ts) if own else build_loop(spec, ts)
            _ = lp.nominal  # the model loop must be stable too: learning filters invert it
        except (UnstableLoopError, SpecError) as exc:
            text = str(exc).removeprefix(f"system {spec.name!r}: ")  # build_loop names the system already; say it once
            text = text.removeprefix(f"vehicle {spec.name!r}: ")
            keys = ("" if not isinstance(exc, UnstableLoopError) else
                    ", key `channel_map`" if own else ", keys `controller`/`dob`/`plant`")
            raise FleetError(f"{source}: system {spec.name!r}{keys}: {text}") from exc
        loops.append(lp)
    return Fleet(sample_time=ts, systems=tuple(systems), loops=tuple(loops), source=source)


def load_fleet(path: str | Path, axis: str = "x") -> Fleet:
    """Load and validate a fleet TOML file.

    Parameters
    ----------
    path : str or Path
        The fleet file (schema: module docstring).
    axis : {"x", "y", "z"}
        The axis whose fleet is loaded (x: the paper's; y and z from the per-axis sections).

    Returns
    -------
    Fleet
        Every system with its built, stability-checked loop; ``source`` is ``path``.

    Notes
    -----
    Relative model-file paths (``plant = { model = "uav4.json" }``) are relative to the fleet
    file's folder.

    Raises
    ------
    FleetError
        Unreadable file, TOML syntax error, missing or unknown keys, invalid values, an
        unreadable or malformed model file, improper ``M``, or an unstable loop; the message
        names the file, system and key.
    """
    path = Path(path)
    _, data = read_fleet_file(path)
    return fleet_from_dict(data, str(path), base_dir=path.parent, axis=axis)


def read_fleet_file(path: str | Path) -> tuple[str, dict[str, Any]]:
    """The text of a fleet file and its parsed TOML table (not yet validated).

    Parameters
    ----------
    path : str or Path
        The fleet file.

    Returns
    -------
    text : str
        The file's content.
    data : dict
        Its parsed TOML table.

    Raises
    ------
    FleetError
        Unreadable file, not a regular file (a FIFO, a device), larger than
        :data:`ilcdob.inputs.MAX_DOCUMENT_BYTES`, not UTF-8 text, TOML syntax error, a number
        beyond float range or nesting deeper than :data:`ilcdob.inputs.MAX_NESTING`, naming the
        file.
    """
    path = Path(path)
    text = read_text(path, "fleet file", error=FleetError, hint="a fleet file is TOML text (schema: ilcdob.fleet)")
    return text, parse_toml(text, path, "fleet file", error=FleetError)


#: How results name the built-in fleet (package-relative: no machine path in any output).
DEFAULT_FLEET_SOURCE = "ilcdob/data/default_fleet.toml"


def default_fleet() -> Fleet:
    """The built-in fleet: the paper's three UAVs (Table I), see ``data/default_fleet.md``.

    Its ``source`` is :data:`DEFAULT_FLEET_SOURCE`, a package-relative name, so results and
    reports written from it carry no path of the machine they ran on.
    """
    return replace(load_fleet(DEFAULT_FLEET_PATH), source=DEFAULT_FLEET_SOURCE)
