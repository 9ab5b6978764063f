"""Fleets: several systems flying the same task, loaded from TOML.

Schema (one ``[[system]]`` table per vehicle; units in comments)::

    sample_time = 0.02                      # s
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

Every system's loops are built (and checked for stability) when the fleet is loaded. Any
problem raises :class:`~ilcdob.errors.FleetError` naming the file, the system and the key.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from .errors import FleetError, SpecError, UnstableLoopError
from .loop import LoopSystem, build_loop
from .specs import DOBSpec, IdentificationSpec, NoiseSpec, PIDSpec, PlantSpec, SystemSpec, UncertaintySpec

__all__ = ["Fleet", "load_fleet", "default_fleet", "DEFAULT_FLEET_PATH", "fleet_from_dict"]

DEFAULT_FLEET_PATH = Path(str(resources.files("ilcdob") / "data" / "default_fleet.toml"))

_TOP_KEYS = {"sample_time": True, "system": True, "description": False}
_SYSTEM_KEYS = {"name": True, "plant": True, "controller": True, "dob": True,
                "delay": False, "model": False, "noise": False, "identification": False, "uncertainty": False}
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
}
_SPEC_CLASS = {"plant": PlantSpec, "model": PlantSpec, "controller": PIDSpec, "dob": DOBSpec,
               "noise": NoiseSpec, "identification": IdentificationSpec, "uncertainty": UncertaintySpec}


@dataclass(frozen=True)
class Fleet:
    """Systems sharing a sample time, in file order.

    Attributes
    ----------
    sample_time : float
        s.
    systems : tuple of SystemSpec
    loops : tuple of LoopSystem
        Built, stability-checked loops, one per system.
    source : str
        Where the fleet came from (file path), for messages.
    """

    sample_time: float
    systems: tuple[SystemSpec, ...]
    loops: tuple[LoopSystem, ...]
    source: str = "<memory>"

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.systems]

    def loop(self, name: str) -> LoopSystem:
        """The loop of system ``name``."""
        for lp in self.loops:
            if lp.name == name:
                return lp
        raise FleetError(f"{self.source}: no system named {name!r}; the fleet has {self.names}")


def _check_keys(where: str, table: Any, spec: dict[str, bool]) -> None:
    if not isinstance(table, dict):
        raise FleetError(f"{where}: expected a table, got {table!r}")
    unknown = sorted(set(table) - set(spec))
    if unknown:
        raise FleetError(f"{where}: unknown key(s) {unknown}; valid keys are {sorted(spec)}")
    missing = sorted(k for k, req in spec.items() if req and k not in table)
    if missing:
        raise FleetError(f"{where}: missing key(s) {missing}")


def _system_from_table(src: str, idx: int, table: Any) -> SystemSpec:
    label = f"{src}: system #{idx + 1}"
    if isinstance(table, dict) and isinstance(table.get("name"), str):
        label = f"{src}: system {table['name']!r}"
    _check_keys(label, table, _SYSTEM_KEYS)
    parts: dict[str, Any] = {}
    for key, keys in _TABLE_KEYS.items():
        if key not in table:
            continue
        _check_keys(f"{label}, key `{key}`", table[key], keys)
        kwargs = dict(table[key])
        if key == "plant":
            kwargs["delay"] = table.get("delay", 0.0)
        try:
            parts[key] = _SPEC_CLASS[key](**kwargs)
        except SpecError as exc:
            raise FleetError(f"{label}, key `{key}`: {exc}") from exc
        except TypeError as exc:
            raise FleetError(f"{label}, key `{key}`: {exc}") from exc
    try:
        return SystemSpec(name=table["name"], **parts)
    except SpecError as exc:
        raise FleetError(f"{label}: {exc}") from exc


def fleet_from_dict(data: dict[str, Any], source: str = "<memory>") -> Fleet:
    """Validate a parsed fleet table and build its loops (see module docstring)."""
    _check_keys(source, data, _TOP_KEYS)
    ts = data["sample_time"]
    if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not ts > 0:
        raise FleetError(f"{source}: key `sample_time`: got {ts!r}, expected a number > 0 (s)")
    tables = data["system"]
    if not isinstance(tables, list) or not tables:
        raise FleetError(f"{source}: key `system`: expected one or more [[system]] tables")
    systems = [_system_from_table(source, i, t) for i, t in enumerate(tables)]
    names = [s.name for s in systems]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FleetError(f"{source}: key `name`: duplicated system name(s) {dup}")
    loops = []
    for spec in systems:
        try:
            lp = build_loop(spec, float(ts))
            _ = lp.nominal  # the model loop must be stable too: learning filters invert it
        except UnstableLoopError as exc:
            raise FleetError(f"{source}: system {spec.name!r}, keys `controller`/`dob`/`plant`: {exc}") from exc
        except SpecError as exc:
            raise FleetError(f"{source}: system {spec.name!r}: {exc}") from exc
        loops.append(lp)
    return Fleet(sample_time=float(ts), systems=tuple(systems), loops=tuple(loops), source=source)


def load_fleet(path: str | Path) -> Fleet:
    """Load and validate a fleet TOML file.

    Raises
    ------
    FleetError
        Unreadable file, TOML syntax error, missing or unknown keys, invalid values,
        improper ``M``, or an unstable loop; the message names the file, system and key.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FleetError(f"{path}: cannot read fleet file ({exc.strerror})") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FleetError(f"{path}: not valid TOML: {exc}") from exc
    return fleet_from_dict(data, str(path))


def default_fleet() -> Fleet:
    """The built-in fleet: the paper's three UAVs (Table I), see ``data/default_fleet.md``."""
    return load_fleet(DEFAULT_FLEET_PATH)
