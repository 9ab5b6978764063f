"""Example flight logs for the README's Python route, made on the spot.

:func:`write_example_flights` writes ``UAV1_chirp.csv`` and ``UAV4_chirp.csv``: 40 s of
closed-loop flight (the PID and the DOB of the paper's loop, Fig. 2) of two vehicles whose
x axis is ``b0 / (s^2 (s + a0)) e^{-s delay}`` (:data:`EXAMPLE_VEHICLES`), with reference steps
of 5 cm, a chirp of 0.1 to 2 Hz injected on the acceleration command (the excitation of an
identification flight) and 1 mm of position noise. The columns are those of a logged
flight: ``time`` (s), ``acc_cmd`` (the acceleration command, m/s^2) and ``x`` (the measured
position, m). Replace them with logs of your own vehicles; the files are the same on every
call (the noise is seeded), so running the route twice gives the same fleet.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .specs import DOBSpec, PIDSpec

__all__ = ["ExampleVehicle", "EXAMPLE_VEHICLES", "EXAMPLE_SAMPLE_TIME", "write_example_flights"]

#: Sample time of the example flights, s.
EXAMPLE_SAMPLE_TIME = 0.02


@dataclass(frozen=True)
class ExampleVehicle:
    """The truth behind one example flight.

    Attributes
    ----------
    a0 : float
        The drag pole, 1/s.
    b0 : float
        The gain, m/s^2 of acceleration per unit command, times 1/s.
    delay : float
        Input delay, s.
    controller : PIDSpec
        The PID it flies.
    dob : DOBSpec
        Its disturbance observer.
    """

    a0: float
    b0: float
    delay: float
    controller: PIDSpec
    dob: DOBSpec = DOBSpec(q_order=3, q_time_constant=0.15)


#: The two example vehicles: a stiffly controlled one without delay and a softer one with 30 ms.
EXAMPLE_VEHICLES = {
    "UAV1": ExampleVehicle(10.0, 10.4, 0.0, PIDSpec(kp=3.0, ki=0.3, kd=2.4, derivative_filter=0.05)),
    "UAV4": ExampleVehicle(7.2, 7.4, 0.03, PIDSpec(kp=1.2, ki=0.12, kd=1.53, derivative_filter=0.05)),
}


def write_example_flights(folder: str | os.PathLike = ".", duration: float = 40.0) -> list[Path]:
    """Write ``<name>_chirp.csv`` for every vehicle of :data:`EXAMPLE_VEHICLES` into ``folder``.

    Parameters
    ----------
    folder : str or os.PathLike
        Where the logs go (created if needed); each is written atomically.
    duration : float
        Length of each flight, s (at least 10: one reference step and the chirp's low end).

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    SpecError
        ``duration`` is not a number of at least 10 s.
    """
    import control as ct

    from .errors import SpecError
    from .loop import build_loop
    from .signals import FlightData
    from .specs import PlantSpec, SystemSpec

    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not (10.0 <= duration <= 3600.0):
        raise SpecError(f"`duration`: got {duration!r}, expected a flight length of 10 to 3600 s")
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    ts = EXAMPLE_SAMPLE_TIME
    t = np.arange(int(round(duration / ts))) * ts
    r = 0.05 * np.sign(np.sin(2 * np.pi * t / 10.0))
    chirp = np.sin(2 * np.pi * (0.1 * t + (2.0 - 0.1) * t**2 / (2 * t[-1])))
    written = []
    for seed, (name, v) in enumerate(EXAMPLE_VEHICLES.items()):
        plant = PlantSpec.from_lti(ct.tf([v.b0], [1.0, v.a0, 0.0, 0.0]), delay=v.delay)
        loop = build_loop(SystemSpec(name, plant, v.controller, v.dob), ts)
        outputs = ct.forced_response(loop.closed_loop, T=t, U=np.vstack([r, 0 * t, chirp])).outputs
        x = outputs[0] + 0.001 * np.random.default_rng(seed).standard_normal(t.size)
        path = out / f"{name}_chirp.csv"
        FlightData(t, {"acc_cmd": outputs[3], "x": x}, {"acc_cmd": "m/s^2", "x": "m"},
                   source=f"example flight of {name}").to_csv(path)
        written.append(path)
    return written
