"""The in-house quadrotor as a vehicle of the protocol (:mod:`ilcdob.vehicles.quadrotor_vehicle`), axes held by a
PID alone in :func:`~ilcdob.vehicles.interface.fly_vehicle`, and the one fleet identification of
:func:`~ilcdob.validation.vehicle_chain.identify_vehicles` with experiments of one's own."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ilcdob
from ilcdob.errors import SpecError
from ilcdob.specs import DOBSpec, PIDSpec, PlantSpec
from ilcdob.uncertainty import ModelStructure
from ilcdob.vehicles.interface import Vehicle, fly_vehicle
from ilcdob.vehicles.quadrotor import fly, table_i_vehicles
from ilcdob.vehicles.quadrotor_vehicle import QuadrotorVehicle

FLEET = ilcdob.default_fleet()
TS = FLEET.sample_time


def test_through_the_protocol_it_flies_the_flights_of_fly_to_the_bit():
    """A step and chirp flight under the fleet's PID (x and y) and the vehicle's z PID, wind on the airframe,
    sensor noise: :func:`~ilcdob.vehicles.quadrotor.fly` (its own loop) and the vehicle flown by
    ``fly_vehicle`` with every axis a PID alone give the same command, measurement and true position."""
    params = table_i_vehicles()["UAV2"]
    spec = next(s for s in FLEET.systems if s.name == "UAV2")
    ref = lambda t: 0.05 * (np.asarray(t) >= 1.0)  # noqa: E731
    inj = lambda t: 0.8 * np.sin(2 * np.pi * 0.7 * np.asarray(t))  # noqa: E731
    wind = lambda t: 0.3 * np.sin(1.1 * np.asarray(t))  # noqa: E731
    log = fly(params, spec, 6.0, TS, reference=ref, injection=inj, disturbance=wind, noise_std=5e-4, seed=7)
    n = log["x"].size
    t = np.arange(n) * TS
    vehicle = QuadrotorVehicle(params, TS, disturbance=wind, noise_std=5e-4, seed=7, horizon=n)
    assert isinstance(vehicle, Vehicle)
    pid = spec.controller
    trial = fly_vehicle(vehicle, {"x": pid, "y": pid, "z": params.z_controller}, {"x": ref(t)},
                        feedforward={"x": inj(t)}, dob=False)
    assert np.array_equal(trial.applied[:, 0], log["acc_cmd"])
    assert np.array_equal(trial.y_meas[:, 0], log["x"])
    assert np.array_equal(np.array(vehicle.truth), np.column_stack([log["x_true"], log["y_true"], log["z_true"]]))
    assert np.all(trial.d_hat == 0)


def test_reset_repeats_the_trial_and_the_disturbance_needs_no_horizon():
    params = table_i_vehicles()["UAV1"]
    loop = FLEET.loop("UAV1")
    n = 200
    r = 0.2 * np.sin(np.arange(n) * TS)
    wind = lambda t: 0.5 * np.cos(0.8 * np.asarray(t))  # noqa: E731
    loops = {"x": loop, "y": loop.spec.controller, "z": params.z_controller}
    seed = np.random.SeedSequence([3, 1001, 0, 2])
    vehicle = QuadrotorVehicle(params, TS, disturbance=wind, noise_std=5e-4, seed=seed, horizon=n)
    first = fly_vehicle(vehicle, loops, {"x": r})
    again = fly_vehicle(vehicle, loops, {"x": r})  # reset: hover at the origin, the same noise
    lazy = fly_vehicle(QuadrotorVehicle(params, TS, disturbance=wind, noise_std=5e-4, seed=seed), loops, {"x": r})
    for other in (again, lazy):
        assert np.array_equal(first.y_meas, other.y_meas) and np.array_equal(first.d_hat, other.d_hat)
    assert len(vehicle.truth) == n and vehicle.saturated == 0


def test_the_tilt_limit_scales_the_horizontal_command_and_is_counted():
    params = table_i_vehicles()["UAV1"]
    vehicle = QuadrotorVehicle(params, TS)
    applied = vehicle.step(np.array([30.0, 0.0, 0.0]))
    assert applied[0] == pytest.approx(9.81 * math.tan(params.max_tilt)) and vehicle.saturated == 1
    assert vehicle.step(np.zeros(3)).tolist() == [0.0, 0.0, 0.0] and vehicle.saturated == 1
    vehicle.reset()
    assert vehicle.saturated == 0 and vehicle.position().tolist() == [0.0, 0.0, 0.0]


def test_vehicle_and_pid_axis_errors_name_what_is_wrong():
    params = table_i_vehicles()["UAV1"]
    with pytest.raises(SpecError, match="`params`"):
        QuadrotorVehicle("UAV1", TS)
    with pytest.raises(SpecError, match="`inner_rate_hz` of vehicle 'UAV1'"):
        QuadrotorVehicle(params, 0.0213)
    with pytest.raises(SpecError, match="`disturbance`"):
        QuadrotorVehicle(params, TS, disturbance=np.zeros(10))
    with pytest.raises(SpecError, match="`noise_std`"):
        QuadrotorVehicle(params, TS, noise_std=-1.0)
    vehicle = QuadrotorVehicle(params, TS)
    with pytest.raises(SpecError, match="`command`"):
        vehicle.step(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(SpecError, match="`command`"):
        vehicle.step(np.zeros(2))
    loop = FLEET.loop("UAV1")
    pid = loop.spec.controller
    with pytest.raises(SpecError, match="axis 'y' flies its PID alone"):
        fly_vehicle(vehicle, {"x": loop, "y": pid, "z": pid}, np.zeros((5, 3)), learning={"y": np.ones(5)})
    with pytest.raises(SpecError, match=r"`loops\['z'\]`: got str"):
        fly_vehicle(vehicle, {"x": loop, "y": pid, "z": "pid"}, np.zeros((5, 3)))


class _Stub:
    """Experiments without flights: a fixed fit per vehicle (structure with relative degree 4)."""

    axis = "x"

    def __init__(self):
        self.calls = []

    def fit(self, name, index):
        from ilcdob.validation.vehicle_chain import VehicleFit

        self.calls.append((name, index))
        st = ModelStructure(n_poles=4, n_integrators=2)
        plant = PlantSpec((10.4,), (0.01, 1.103, 10.3, 0.0, 0.0))
        return VehicleFit(name, st, plant, {VehicleFit.label(st): 97.5 + index}, 98.0, None, record=index)


def test_identify_vehicles_builds_the_fleet_of_any_experiments():
    """One routine for every vehicle: the fit is the plant, the DOB's Q order is raised to the model's
    relative degree, the base fleet's noise stays, progress after each vehicle."""
    from ilcdob.validation.vehicle_chain import identify_vehicles

    stub, said = _Stub(), []
    fleet, fits = identify_vehicles(stub, FLEET.names, None, None, TS, base=FLEET,
                                    progress=lambda *a: said.append(a))
    assert stub.calls == [(n, i) for i, n in enumerate(FLEET.names)]
    assert [f.record for f in fits.values()] == [0, 1, 2]
    for old, new in zip(FLEET.systems, fleet.systems):
        assert new.plant == PlantSpec((10.4,), (0.01, 1.103, 10.3, 0.0, 0.0)) and new.model is None
        assert new.controller == old.controller and new.noise == old.noise
        assert new.dob.q_order == max(4, old.dob.q_order)
    assert said[0] == (1, 3, "identified UAV1: fit 98.00 % (estimation), 97.50 % (held out)")
    alone, _ = identify_vehicles(stub, ["UAV1"], {"UAV1": PIDSpec(2.5, 0.3, 2.2, 0.05)}, {"UAV1": DOBSpec(3, 0.2)},
                                 TS)
    assert alone.systems[0].dob == DOBSpec(4, 0.2) and alone.axis == "x"
    with pytest.raises(SpecError, match="carry their own"):
        identify_vehicles(stub, ["UAV1"], None, None, TS, 10.0, base=FLEET)
    with pytest.raises(SpecError, match="without a `base`"):
        identify_vehicles(stub, ["UAV1"], None, None, TS)


def test_the_nonlinear_identification_is_the_fleet_file_of_its_fits():
    """The in-house quadrotors' step and chirp experiments through ``identify_vehicles``: the fleet of the
    models is the fleet file that :func:`~ilcdob.identification.fleet_id.identified_systems` writes of the
    same fits (one vehicle, about 2 s)."""
    import tomllib

    from ilcdob.fleet import fleet_from_dict
    from ilcdob.fleet_io import fleet_to_toml
    from ilcdob.identification.fleet_id import identified_systems
    from ilcdob.validation.nonlinear import NonlinearSettings, _identify

    one = ilcdob.fleet.fleet_from_systems([FLEET.systems[2]], TS, "one.toml")
    models, ident, text = _identify(one, table_i_vehicles(), NonlinearSettings(seed=4))
    assert list(ident) == ["UAV3"] and ident["UAV3"].estimate.fit_validation > 95.0
    want = fleet_to_toml(TS, identified_systems(one, ident), header=text.splitlines()[0])
    assert text == want
    assert models.systems == fleet_from_dict(tomllib.loads(want), "identified_fleet.toml").systems
