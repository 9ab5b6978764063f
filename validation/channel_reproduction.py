"""The paper's scenarios on vehicles flying their own controllers (docs/closed_loop.md).

What ``ilcdob reproduce --plant rotorpy --controller own`` runs: rotorpy's multirotors (a simulator nobody
here wrote) on rotorpy's own SE3 position controller, no ilcdob controller (the add-on DOB only when
asked), the learning signal on a setpoint channel. Per channel:

1. every vehicle's channel is identified on every axis a scenario learns
   (:func:`~.channel_chain.identify_channel_loops`: two chirp flights per axis, the airframe fitted from the
   logged commanded acceleration);
2. every scenario is flown (:func:`~.channel_chain.fly_channel_chain`, the scenario's learning order, its
   reference from where the vehicles start) in the paper's disturbance with the paper's law, and in Dryden
   turbulence with the wind law and, in hover for comparison, the paper's.

The vehicles are rotorpy's hummingbird and crazyflie (with position gains of our own) and an airframe of our
own making unlike rotorpy's (:data:`LAB_QUAD`: 1.4 kg, arms 1.5 times the hummingbird's); a lab passes its
own (:class:`ChannelVehicle`). Units: s, m, m/s^2.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.specs import DOBSpec
from ilcdob.channel_loop import check_channel

from .channel_chain import ChannelChain, fly_channel_chain, identify_channel_loops
from .channel_id import ChannelFit
from .scenarios import scenario
from .vehicle_chain import dryden_gust, vehicle_reference

__all__ = ["ChannelVehicle", "ChannelSettings", "ChannelRun", "ChannelReproduction", "reproduce_channels",
           "lab_quad_airframe", "load_vehicles", "DEFAULT_VEHICLES", "RUNS", "runs_of"]


def lab_quad_airframe() -> dict[str, Any]:
    """An airframe of our own making (module docstring): rotorpy's hummingbird set with 1.4 kg, inertias
    0.012 / 0.012 / 0.022 kg m^2 and rotor positions 1.5 times as far out.

    Returns
    -------
    dict
        A complete rotorpy parameter set (:class:`~ilcdob.vehicles.rotorpy_vehicle.RotorpyVehicle`'s ``airframe``).
    """
    from ilcdob.vehicles.rotorpy_vehicle import shipped_airframe

    base = shipped_airframe("hummingbird")
    return {**base, "mass": 1.4, "Ixx": 0.012, "Iyy": 0.012, "Izz": 0.022,
            "rotor_pos": {k: 1.5 * np.asarray(v) for k, v in base["rotor_pos"].items()}}


@dataclass(frozen=True)
class ChannelVehicle:
    """One vehicle of the run.

    Attributes
    ----------
    name : str
    airframe : str or mapping or None
        A rotorpy parameter set's name, a complete set of a lab's own, or None: ``name``'s shipped set.
    position_gains : (tuple, tuple) or None
        ``(kp, kd)`` of its SE3 position loop per axis (1/s^2, 1/s); None: rotorpy's.
    """

    name: str
    airframe: str | Mapping[str, Any] | None = None
    position_gains: tuple[tuple[float, ...], tuple[float, ...]] | None = None


#: Keys of one ``[[vehicle]]`` table of a vehicles file (:func:`load_vehicles`); True: required.
_VEHICLE_KEYS = {"name": True, "airframe": False, "params": False, "position_gains": False}


def load_vehicles(path: str | Path) -> tuple[ChannelVehicle, ...]:
    """A lab's airframes for a rotorpy run, from a TOML file (``reproduce --plant rotorpy --vehicles FILE``)::

        description = "our fleet"            # optional
        [[vehicle]]
        name = "heavy"
        airframe = "hummingbird"             # the rotorpy set to start from (default: name, if rotorpy ships it)
        params = { mass = 2.0, Ixx = 0.03, Iyy = 0.03, Izz = 0.05 }    # changes to it, rotorpy's keys and SI units
        position_gains = { kp = [4.0, 4.0, 10.0], kd = [3.0, 3.0, 7.0] }   # SE3 position loop (default rotorpy's;
                                                                            # --controller own only)

    ``params`` may replace nested values whole (``rotor_pos = { r1 = [0.2, 0.2, 0], ... }``, m).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    tuple of ChannelVehicle
        In file order, each with its complete parameter set.

    Raises
    ------
    SpecError
        An unreadable file, unknown or missing keys, a bad name, an airframe rotorpy does not ship, a parameter no
        rotorpy set has, or gains that are not three positive numbers each; the message names the file, the
        vehicle and the key.
    """
    from ilcdob.inputs import parse_toml, read_text
    from ilcdob.names import check_name
    from ilcdob.vehicles.rotorpy_vehicle import ROTORPY_VEHICLES, airframe_parameters, shipped_airframe

    path = Path(path)
    data = parse_toml(read_text(path, "vehicles file", error=SpecError, hint="a vehicles file is TOML text"), path,
                      "vehicles file", error=SpecError)
    unknown = sorted(set(data) - {"description", "vehicle"})
    tables = data.get("vehicle")
    if unknown or not isinstance(tables, list) or not tables:
        raise SpecError(f"{path}: expected [[vehicle]] tables (and an optional `description`)"
                        + (f"; unknown key(s) {unknown}" if unknown else ""))
    out = []
    for i, table in enumerate(tables):
        label = f"{path}: vehicle #{i + 1}"
        if not isinstance(table, dict):
            raise SpecError(f"{label}: expected a table")
        bad = sorted(set(table) - set(_VEHICLE_KEYS))
        if bad or "name" not in table:
            raise SpecError(f"{label}: " + (f"unknown key(s) {bad}; " if bad else "missing key `name`; ")
                            + f"valid keys are {sorted(_VEHICLE_KEYS)}")
        try:
            name = check_name(table["name"])
        except SpecError as exc:
            raise SpecError(f"{label}: {exc}") from None
        label = f"{path}: vehicle {name!r}"
        base = table.get("airframe", name)
        if base not in ROTORPY_VEHICLES:
            raise SpecError(f"{label}, key `airframe`: got {base!r}, expected a parameter set rotorpy ships "
                            f"({sorted(ROTORPY_VEHICLES)}) to start from, changed by `params`")
        params = table.get("params", {})
        if not isinstance(params, dict):
            raise SpecError(f"{label}, key `params`: got {params!r}, expected a table of rotorpy parameters")
        try:
            airframe = airframe_parameters({**shipped_airframe(base), **params})
        except SpecError as exc:
            raise SpecError(f"{label}, key `params`: {exc}") from None
        out.append(ChannelVehicle(name, airframe, _gains(label, table.get("position_gains"))))
    return tuple(out)


def _gains(label: str, table: Any) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """``position_gains = { kp = [...], kd = [...] }`` as ``(kp, kd)``; None when not given."""
    if table is None:
        return None
    if not isinstance(table, dict) or set(table) != {"kp", "kd"}:
        raise SpecError(f"{label}, key `position_gains`: got {table!r}, expected {{ kp = [x, y, z], kd = [x, y, z] }} "
                        "(1/s^2, 1/s)")
    gains = []
    for key in ("kp", "kd"):
        v = table[key]
        if (not isinstance(v, list) or len(v) != 3
                or not all(isinstance(g, (int, float)) and not isinstance(g, bool) and np.isfinite(g) and g > 0
                           for g in v)):
            raise SpecError(f"{label}, key `position_gains.{key}`: got {v!r}, expected three gains > 0 (x, y, z)")
        gains.append(tuple(float(g) for g in v))
    return gains[0], gains[1]


#: The run's vehicles (module docstring); ``"lab-quad"``'s airframe is :func:`lab_quad_airframe`'s.
DEFAULT_VEHICLES = (ChannelVehicle("hummingbird"),
                    ChannelVehicle("crazyflie", position_gains=((3.0, 3.0, 10.0), (3.0, 3.0, 6.0))),
                    ChannelVehicle("lab-quad", "lab-quad", ((4.0, 4.0, 10.0), (3.0, 3.0, 7.0))))


@dataclass(frozen=True)
class ChannelSettings:
    """What the run flies (module docstring).

    Attributes
    ----------
    vehicles : tuple of ChannelVehicle
        At least two.
    channels : tuple of str
        The learning channels flown, each a whole run.
    ts : float
        Setpoint period, s.
    sensor_noise_std : float
        White position-sensor noise, m.
    trial_s : float
        Length of every learning trial, s (the paper's scenarios are 40-60 s; 30 s keeps the run short).
    identification_s : float
        Length of each identification flight, s.
    dob : DOBSpec or None
        Fly the add-on DOB of this ``Q`` on every vehicle.
    dryden_wind_20ft : float
        Dryden turbulence's mean wind at 20 ft, m/s.
    dryden_seed : int
        Seed of its frozen field.
    identified_axes : tuple of str
        Axes whose channel maps are identified and reported besides those the scenarios learn on (x, and y
        where the path moves laterally).
    """

    vehicles: tuple[ChannelVehicle, ...] = DEFAULT_VEHICLES
    channels: tuple[str, ...] = ("acceleration", "position")
    ts: float = 0.01
    sensor_noise_std: float = 5e-4
    trial_s: float = 30.0
    identification_s: float = 30.0
    dob: DOBSpec | None = None
    dryden_wind_20ft: float = 2.0
    dryden_seed: int = 7
    identified_axes: tuple[str, ...] = ("x", "y", "z")

    def __post_init__(self) -> None:
        if len(self.vehicles) < 2 or not all(isinstance(v, ChannelVehicle) for v in self.vehicles):
            raise SpecError(f"`vehicles`: got {self.vehicles!r}, expected at least two ChannelVehicle")
        names = [v.name for v in self.vehicles]
        if len(set(names)) != len(names):
            raise SpecError(f"`vehicles`: names {names} repeat; each vehicle needs its own")
        if not self.channels:
            raise SpecError("`channels`: got none, expected some of 'position', 'velocity', 'acceleration'")
        for ch in self.channels:
            check_channel(ch, "channels")
        bad = [ax for ax in self.identified_axes if ax not in ("x", "y", "z")]
        if bad:
            raise SpecError(f"`identified_axes`: got {list(self.identified_axes)}, expected some of ['x', 'y', 'z']")
        for what in ("ts", "trial_s", "identification_s"):
            value = getattr(self, what)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise SpecError(f"`{what}`: got {value!r}, expected a time > 0 s")
        if not (np.isfinite(self.sensor_noise_std) and self.sensor_noise_std >= 0):
            raise SpecError(f"`sensor_noise_std`: got {self.sensor_noise_std!r}, expected a standard deviation >= 0 m")

    def make(self) -> Callable:
        """``make(name, seed, command_disturbance, wind)``: a fresh rotorpy vehicle of the run at rest."""
        from ilcdob.vehicles.rotorpy_vehicle import RotorpyVehicle

        by_name = {v.name: v for v in self.vehicles}

        def make(name, seed, cmd=None, wind=None):
            v = by_name[name]
            airframe = lab_quad_airframe() if v.airframe == "lab-quad" else v.airframe
            return RotorpyVehicle(name, self.ts, noise_std=self.sensor_noise_std, seed=seed, airframe=airframe,
                                  command_disturbance=cmd, wind=wind, position_gains=v.position_gains)

        return make


#: The runs of every scenario: (disturbance, law as :func:`~ilcdob.design.pair.design_channel_pair`'s ``disturbance``);
#: the paper's law in Dryden turbulence, for comparison, in hover only (:func:`runs_of`).
RUNS = (("paper", "command"), ("dryden", "wind"), ("dryden", "command"))


def runs_of(sid: int) -> tuple[tuple[str, str], ...]:
    """The runs of a scenario (:data:`RUNS`).

    Parameters
    ----------
    sid : int
        Scenario id.

    Returns
    -------
    tuple of (str, str)
        Its (disturbance, law) pairs.
    """
    return RUNS if sid == 1 else RUNS[:2]


@dataclass(frozen=True)
class ChannelRun:
    """One chain: a scenario on one channel in one disturbance with one law.

    Attributes
    ----------
    scenario : int
    channel : str
    disturbance : {"paper", "dryden"}
    law : {"command", "wind"}
        Where the law assumes the disturbance acts (``"command"``: the paper's law).
    axes : tuple of str
    order : list of str
    baseline_rmse : dict of str to float
        Each vehicle's RMSE without learning (with the add-on DOB where it flies one), m.
    ratios : dict of str to list of float
        Each learning flight's RMSE over that, per vehicle.
    """

    scenario: int
    channel: str
    disturbance: str
    law: str
    axes: tuple[str, ...]
    order: list[str]
    baseline_rmse: dict[str, float]
    ratios: dict[str, list[float]]

    @classmethod
    def of(cls, sid: int, channel: str, disturbance: str, law: str, chain: ChannelChain) -> "ChannelRun":
        """The figures of one flown chain.

        Parameters
        ----------
        sid : int
            Its scenario.
        channel, disturbance, law : str
            As the attributes.
        chain : ChannelChain
            Its flights (:func:`~.channel_chain.fly_channel_chain`).

        Returns
        -------
        ChannelRun
        """
        return cls(sid, channel, disturbance, law, chain.axes, list(chain.order),
                   {n: chain.rmse(chain.baseline[n]) for n in chain.order}, chain.ratios())


@dataclass(frozen=True)
class ChannelReproduction:
    """The run's identification and chains (module docstring).

    Attributes
    ----------
    settings : ChannelSettings
    iterations : int
    fits : dict
        ``fits[channel][vehicle][axis]``: :class:`~.channel_id.ChannelFit`.
    runs : list of ChannelRun
    elapsed_s : float
        Wall time of the run, s.
    """

    settings: ChannelSettings
    iterations: int
    fits: dict[str, dict[str, dict[str, ChannelFit]]]
    runs: list[ChannelRun] = field(default_factory=list)
    elapsed_s: float = 0.0

    def acceptance(self) -> list[dict[str, object]]:
        """Each acceptance figure: held-out fit >= 95 % per channel, vehicle and axis; the paper's disturbance in
        hover, learning 1 <= 0.10 of no learning (<= 0.05 with the add-on DOB); on the diamond, iteration 3
        (the last) <= 0.25 without the DOB; Dryden with the wind law, every iteration <= 0.5 and none worse than
        without learning."""
        def row(what: str, value: float, limit: float, at_least: bool = False) -> dict[str, object]:
            return {"what": what, "value": float(value), "limit": limit,
                    "passed": bool(value >= limit if at_least else value <= limit)}

        rows = [row(f"held-out fit, {ch}, {name}, {ax} (%)", f.fit_validation, 95.0, True)
                for ch, per in self.fits.items() for name, axes in per.items() for ax, f in axes.items()]
        hover = 0.05 if self.settings.dob is not None else 0.10
        for r in self.runs:
            for name in r.order:
                what = f"{r.disturbance}, scenario {r.scenario}, {r.channel}, {name}"
                if r.disturbance == "paper" and r.scenario == 1:
                    rows.append(row(f"{what}: learning 1 / no learning", r.ratios[name][0], hover))
                if r.disturbance == "paper" and r.scenario == 4 and self.settings.dob is None:
                    rows.append(row(f"{what}: learning {len(r.ratios[name])} / no learning", r.ratios[name][-1],
                                    0.25))
                if r.disturbance == "dryden" and r.law == "wind":
                    rows.append(row(f"{what} (wind law): worst iteration / no learning", max(r.ratios[name]), 0.5))
        return rows

    def to_dict(self) -> dict[str, object]:
        """The content of ``results.json`` (RMSE in m)."""
        s = self.settings
        return {
            "plant": "rotorpy", "controller": "own", "iterations": self.iterations, "elapsed_s": self.elapsed_s,
            "settings": {"vehicles": [{"name": v.name, "airframe": v.airframe if isinstance(v.airframe, str) or
                                       v.airframe is None else "own parameter set",
                                       **_airframe_summary(v), "position_gains": v.position_gains}
                                      for v in s.vehicles],
                         "channels": list(s.channels), "sample_time": s.ts, "sensor_noise_std": s.sensor_noise_std,
                         "trial_s": s.trial_s, "identification_s": s.identification_s,
                         "dob": None if s.dob is None else {"q_order": s.dob.q_order,
                                                           "q_time_constant": s.dob.q_time_constant},
                         "dryden_wind_20ft": s.dryden_wind_20ft, "dryden_seed": s.dryden_seed},
            "identification": {ch: {name: {ax: {"held_out_fit_percent": f.fit_validation,
                                                "structure": f"{f.structure.n_poles}p{f.structure.n_zeros}z",
                                                "num": list(f.plant.num), "den": list(f.plant.den),
                                                "delay": f.plant.delay, "airframe_fit_percent": f.airframe_fit,
                                                "drag_per_s": f.drag}
                                           for ax, f in axes.items()} for name, axes in per.items()}
                               for ch, per in self.fits.items()},
            "runs": [{"scenario": r.scenario, "channel": r.channel, "disturbance": r.disturbance,
                      "law": "paper" if r.law == "command" else "wind", "axes": list(r.axes), "order": r.order,
                      "rmse_no_learning": r.baseline_rmse, "ratios": r.ratios} for r in self.runs],
            "acceptance": self.acceptance(),
        }

    def markdown(self) -> str:
        """The run's ``README.md``: what was flown, the identification, the tables and the acceptance."""
        s = self.settings
        base = "with the add-on DOB (DOB only)" if s.dob is not None else "without learning"
        lines = [
            "# Learning on the vehicles' own controllers (rotorpy)", "",
            f"rotorpy's multirotors ({', '.join(v.name for v in s.vehicles)}) fly rotorpy's SE3 position controller "
            "(no ilcdob controller"
            + ("" if s.dob is None else f"; the add-on DOB, Q = 1/({s.dob.q_time_constant:g} s + 1)^{s.dob.q_order}")
            + f"), setpoints every {s.ts:g} s, {1e3 * s.sensor_noise_std:g} mm of position noise, "
            f"{s.trial_s:g} s trials, {self.iterations} learning iteration(s); the learning signal on the "
            f"{' or the '.join(s.channels)} channel. Each channel map was identified from two "
            f"{s.identification_s:g} s chirp flights per axis. Disturbances: the paper's (on the command, x) with "
            f"the paper's law; Dryden turbulence ({s.dryden_wind_20ft:g} m/s at 20 ft, the same frozen field of seed "
            f"{s.dryden_seed} every trial) through rotorpy's drag, with the wind law and, in hover, the paper's. "
            f"Ratios are RMSE of the learning flight over the same vehicle's flight {base}. "
            f"Run time {self.elapsed_s / 60:.1f} min. "
            "Regenerate with `ilcdob reproduce --plant rotorpy --controller own --out <dir>` (`--vehicles FILE` "
            "for a lab's airframes) "
            "(needs `pip install 'ilcdob[rotorpy]'`); docs/closed_loop.md explains the law.", "",
            "## Vehicles", "",
            "| vehicle | parameter set | mass (kg) | Ixx, Iyy, Izz (kg m^2) | arm (m) | kp (1/s^2) | kd (1/s) |",
            "|---|---|---|---|---|---|---|",
            *(_vehicle_row(v) for v in s.vehicles), "",
            "## Identification (held-out fit, %)", "",
            "| channel | vehicle | axis | channel map | airframe | drag (1/s) |", "|---|---|---|---|---|---|"]
        for ch, per in self.fits.items():
            for name, axes in per.items():
                for ax, f in axes.items():
                    air = "" if f.airframe_fit is None else f"{f.airframe_fit:.2f}"
                    drag = "" if f.drag is None else f"{f.drag:.3f}"
                    lines.append(f"| {ch} | {name} | {ax} | {f.fit_validation:.2f} | {air} | {drag} |")
        lines += ["", "## Learning", "",
                  "| scenario | disturbance | law | channel | vehicle | no learning (mm) | "
                  + " | ".join(f"iteration {i + 1}" for i in range(self.iterations)) + " |",
                  "|---|---|---|---|---|---|" + "---|" * self.iterations]
        for r in self.runs:
            for name in r.order:
                lines.append(f"| {r.scenario} | {r.disturbance} | {'paper' if r.law == 'command' else 'wind'} | "
                             f"{r.channel} | {name} | {1e3 * r.baseline_rmse[name]:.2f} | "
                             + " | ".join(f"{v:.4f}" for v in r.ratios[name]) + " |")
        lines += ["", "## Acceptance", "", "| figure | measured | limit | met |", "|---|---|---|---|"]
        for row in self.acceptance():
            lines.append(f"| {row['what']} | {row['value']:.4g} | {row['limit']:g} | "
                         f"{'yes' if row['passed'] else 'NO'} |")
        return "\n".join(lines) + "\n"

    def figure(self) -> Any:
        """Learning over iterations: one panel per disturbance and law, a line per scenario, channel and vehicle
        (matplotlib Figure)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        panels = [(d, law) for d, law in RUNS if any(r.disturbance == d and r.law == law for r in self.runs)]
        fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4), squeeze=False)
        for ax, (dist, law) in zip(axes[0], panels):
            for r in (r for r in self.runs if r.disturbance == dist and r.law == law):
                for name in r.order:
                    ax.semilogy(range(1, len(r.ratios[name]) + 1), r.ratios[name], "o-",
                                label=f"sc {r.scenario} {r.channel[:3]} {name}")
            ax.axhline(1.0, color="k", lw=0.8)
            ax.set_xticks(range(1, self.iterations + 1))
            ax.set(title=f"{dist} disturbance, {'paper' if law == 'command' else 'wind'} law",
                   xlabel="learning iteration", ylabel="RMSE / no learning")
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].legend(fontsize=6, ncol=2)
        fig.tight_layout()
        return fig

    def files(self, figures: bool = True) -> dict[str, bytes | str]:
        """The folder's content.

        Parameters
        ----------
        figures : bool
            Include the figure.

        Returns
        -------
        dict of str to str or bytes
            ``README.md``, ``results.json`` and, with ``figures``, ``learning.png``.
        """
        out: dict[str, bytes | str] = {"README.md": self.markdown(),
                                       "results.json": json.dumps(self.to_dict(), indent=2) + "\n"}
        if figures:
            import io

            import matplotlib.pyplot as plt

            fig = self.figure()
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
            plt.close(fig)
            out["learning.png"] = buf.getvalue()
        return out


def _airframe_summary(v: ChannelVehicle) -> dict[str, Any]:
    """Mass (kg), inertias (kg m^2) and mean arm (m) of a run's vehicle
    (:func:`~ilcdob.vehicles.rotorpy_vehicle.airframe_summary`)."""
    from ilcdob.vehicles.rotorpy_vehicle import airframe_summary

    return airframe_summary(lab_quad_airframe() if v.airframe == "lab-quad" else
                            v.name if v.airframe is None else v.airframe)


def _vehicle_row(v: ChannelVehicle) -> str:
    """The README's row of a vehicle."""
    a = _airframe_summary(v)
    base = v.airframe if isinstance(v.airframe, str) else ("rotorpy's" if v.airframe is None else "own")
    gains = ("rotorpy's", "rotorpy's") if v.position_gains is None else tuple(
        ", ".join(f"{g:g}" for g in k) for k in v.position_gains)
    return (f"| {v.name} | {base} | {a['mass_kg']:.3g} | {', '.join(f'{i:.3g}' for i in a['inertia_kg_m2'])} | "
            f"{a['arm_m']:.3g} | {gains[0]} | {gains[1]} |")


def _axes(sid: int) -> tuple[str, ...]:
    """The axes a scenario learns: x, and y where its path moves laterally."""
    return ("x", "y") if scenario(sid).lateral is not None else ("x",)


def reproduce_channels(scenarios: Sequence[int] = (1, 2, 3, 4), iterations: int = 3,
                       settings: ChannelSettings | None = None,
                       progress: Callable[[int, int, str], None] | None = None) -> ChannelReproduction:
    """Identify and fly the run (module docstring).

    Parameters
    ----------
    scenarios : sequence of int
        Scenario ids 1-4.
    iterations : int
        Learning flights per vehicle and chain.
    settings : ChannelSettings, optional
    progress : callable, optional
        ``progress(done, total, what)`` after each identification and each chain.

    Returns
    -------
    ChannelReproduction

    Raises
    ------
    SpecError
        Bad scenarios or settings.
    """
    from .reproduce import check_iterations

    check_iterations(iterations)
    settings = ChannelSettings() if settings is None else settings
    scenarios = list(scenarios)
    for sid in scenarios:
        scenario(sid)  # a bad id fails before any flight
    say = progress if progress is not None else (lambda done, total, what: None)
    t0 = time.perf_counter()
    make = settings.make()
    names = [v.name for v in settings.vehicles]
    axes = tuple(ax for ax in ("x", "y", "z") if any(ax in _axes(sid) for sid in scenarios)
                 or ax in settings.identified_axes)
    total = len(settings.channels) * (1 + sum(len(runs_of(sid)) for sid in scenarios))
    done = 0
    fits, runs = {}, []
    n = int(round(settings.trial_s / settings.ts))
    t = np.arange(n) * settings.ts
    gust = dryden_gust(settings.trial_s + 1.0, settings.ts, settings.dryden_wind_20ft, seed=settings.dryden_seed)
    for ch in settings.channels:
        loops, fits[ch] = identify_channel_loops(make, {nm: ch for nm in names}, settings.ts, axes,
                                                 settings.identification_s, dob=settings.dob)
        done += 1
        say(done, total, f"identified the {ch} channel of {len(names)} vehicles")
        for sid in scenarios:
            sc = scenario(sid)
            ax_sc = _axes(sid)
            ref, acc = vehicle_reference(sc, t, ax_sc)
            vel = np.gradient(ref, settings.ts, axis=0)
            learned = {nm: {ax: loops[nm][ax] for ax in ax_sc} for nm in names}

            def paper(tt, sc=sc):
                return np.array([float(sc.disturbance(np.array([tt]))[0]), 0.0, 0.0])

            for dist, law in runs_of(sid):
                chain = fly_channel_chain(learned, make, ref, sc.order(names), iterations, velocity=vel,
                                          acceleration=acc, command_disturbance=paper if dist == "paper" else None,
                                          wind=gust if dist == "dryden" else None, disturbance=law)
                runs.append(ChannelRun.of(sid, ch, dist, law, chain))
                done += 1
                say(done, total, f"scenario {sid}, {ch} channel, {dist} disturbance, "
                                 f"{'paper' if law == 'command' else 'wind'} law")
    return ChannelReproduction(settings, iterations, fits, runs, time.perf_counter() - t0)
