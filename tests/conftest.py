"""Shared fixtures: the built-in fleet, a writer for fleet files, the C compiler, and a folder of the
session for native libraries."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

import ilcdob


@pytest.fixture(scope="session")
def cc() -> str:
    """The C compiler (`cc` on PATH); the test is skipped without one."""
    path = shutil.which("cc")
    if path is None:
        pytest.skip("no C compiler: `cc` is not on PATH, the emitted C code cannot be compiled")
    return path


@pytest.fixture(scope="session", autouse=True)
def native_libraries(tmp_path_factory):
    """Native libraries (ilcdob/native.py) built by this session go to a folder of its own, not the
    user's cache: every session builds what it uses (as on a fresh machine); commands run as child
    processes inherit it. A folder set by ``ILCDOB_CACHE_DIR`` before the session is kept."""
    if os.environ.get("ILCDOB_CACHE_DIR"):
        yield
        return
    os.environ["ILCDOB_CACHE_DIR"] = str(tmp_path_factory.mktemp("native"))
    try:
        yield
    finally:
        os.environ.pop("ILCDOB_CACHE_DIR", None)


@pytest.fixture(scope="session")
def fleet() -> ilcdob.Fleet:
    return ilcdob.default_fleet()


GOOD_FLEET = """\
sample_time = 0.02
[[system]]
name = "A"
plant = { num = [1.0], den = [0.1, 1.0, 0.0, 0.0] }
delay = 0.0
controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }

[[system]]
name = "B"
plant = { num = [1.0], den = [0.12, 1.0, 0.0, 0.0] }
controller = { kp = 1.2, ki = 0.12, kd = 1.53, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }
"""


@pytest.fixture
def good_fleet_text() -> str:
    """A valid two-system fleet file (schema of ilcdob/fleet.py)."""
    return GOOD_FLEET


@pytest.fixture
def fleet_file(tmp_path: Path):
    """Write a fleet file from text; returns its path."""

    def write(text: str = GOOD_FLEET, name: str = "fleet.toml") -> Path:
        path = tmp_path / name
        path.write_text(text, encoding="utf-8")
        return path

    return write


#: Unequal plants 1/(s^2 (tau s + 1)), tau 0.05 / 0.2 / 0.12 s, the last with a 0.03 s input delay and a
#: fourth-order Q; Ts = 0.01 s; unequal Q time constants (so L2 != 1); exact models, no noise.
UNEQUAL_FLEET = {"sample_time": 0.01, "description": "unequal plants, input delay, q_order 4", "system": [
    {"name": "A1", "plant": {"num": [1.0], "den": [0.05, 1.0, 0.0, 0.0]},
     "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.4, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.15}},
    {"name": "A2", "plant": {"num": [1.0], "den": [0.2, 1.0, 0.0, 0.0]},
     "controller": {"kp": 1.2, "ki": 0.12, "kd": 1.53, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.2}},
    {"name": "A3", "plant": {"num": [1.0], "den": [0.12, 1.0, 0.0, 0.0]}, "delay": 0.03,
     "controller": {"kp": 1.9, "ki": 0.19, "kd": 1.93, "derivative_filter": 0.05},
     "dob": {"q_order": 4, "q_time_constant": 0.15}},
]}

#: Unequal gains and poles (one plant without a second integrator), a fractional-sample delay (0.01 s at
#: Ts = 0.02 s), acceleration feed-forward on only B1 and B3, unequal Q time constants; exact models, no noise.
FEEDFORWARD_FLEET = {"sample_time": 0.02, "description": "unequal plants, mixed acceleration feed-forward", "system": [
    {"name": "B1", "plant": {"num": [2.0], "den": [0.08, 1.0, 0.0, 0.0]},
     "controller": {"kp": 2.0, "ki": 0.2, "kd": 2.0, "derivative_filter": 0.05, "acceleration_feedforward": True},
     "dob": {"q_order": 3, "q_time_constant": 0.1}},
    {"name": "B2", "plant": {"num": [0.8], "den": [0.15, 1.0, 0.0, 0.0]},
     "controller": {"kp": 2.5, "ki": 0.25, "kd": 2.2, "derivative_filter": 0.05, "acceleration_feedforward": False},
     "dob": {"q_order": 3, "q_time_constant": 0.2}},
    {"name": "B3", "plant": {"num": [1.5], "den": [0.1, 1.03, 0.3, 0.0]}, "delay": 0.01,
     "controller": {"kp": 1.5, "ki": 0.15, "kd": 1.6, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.15}},
]}


@pytest.fixture(scope="session")
def unequal_fleet() -> ilcdob.Fleet:
    """Three unequal plants at Ts = 0.01 s, one with an input delay and q_order 4 (:data:`UNEQUAL_FLEET`)."""
    return ilcdob.fleet.fleet_from_dict(UNEQUAL_FLEET, source="unequal_fleet")


@pytest.fixture(scope="session")
def feedforward_fleet() -> ilcdob.Fleet:
    """Three unequal plants at Ts = 0.02 s with mixed acceleration feed-forward (:data:`FEEDFORWARD_FLEET`)."""
    return ilcdob.fleet.fleet_from_dict(FEEDFORWARD_FLEET, source="feedforward_fleet")


#: The rotorpy vehicles identified by :func:`rotorpy_identified`, their sample time and sensor noise.
ROTORPY_NAMES = ("crazyflie", "hummingbird")
ROTORPY_TS = 0.01
ROTORPY_NOISE_STD = 5e-4


def make_rotorpy(name: str, command, wind, seed: int):
    """A fresh rotorpy vehicle at :data:`ROTORPY_TS` with 0.5 mm sensor noise
    (:data:`ilcdob.validation.vehicle_chain.MakeVehicle`)."""
    from ilcdob.vehicles.rotorpy_vehicle import RotorpyVehicle

    return RotorpyVehicle(name, ROTORPY_TS, command_disturbance=command, wind=wind, noise_std=ROTORPY_NOISE_STD,
                          seed=seed)


@pytest.fixture(scope="session")
def rotorpy_identified():
    """The crazyflie and the hummingbird identified from their own flights
    (:func:`ilcdob.validation.vehicle_chain.identify_vehicles`: two 20 s closed-loop chirp flights each, the
    structure with the best held-out fit), the paper's PID and a DOB(3, 0.2) on both: ``(fleet, fits)``.

    Flown once per session for test_vehicle_chain and test_vehicle_interface (about 12 s of CPU): the
    flights are repeatable (seeded sensor noise; rotorpy's motor noise is zero in these parameter sets), so
    every module that identified the pair itself got the same fleet."""
    pytest.importorskip("rotorpy")
    from ilcdob.validation.vehicle_chain import identify_vehicles

    names = list(ROTORPY_NAMES)
    return identify_vehicles(make_rotorpy, names, {n: ilcdob.PIDSpec(2.5, 0.3, 2.2, 0.05) for n in names},
                             {n: ilcdob.DOBSpec(3, 0.2) for n in names}, ROTORPY_TS)
