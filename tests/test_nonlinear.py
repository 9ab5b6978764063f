"""The paper's validation on the nonlinear quadrotors (ilcdob.validation.nonlinear); the learning
law it flies is tested in test_band.py, test_flown.py and test_commands_design.py.

The reproduction's acceptance (``NonlinearReproduction.acceptance``) is checked on a shortened
run (two scenarios of 30 s, the built-in fleet whose plants were identified from these
vehicles) in the default suite, and on the full run (identification included, four
scenarios) behind the ``slow`` marker.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import ilcdob
from ilcdob.app.cli import main
from ilcdob.errors import SpecError
from ilcdob.vehicles.quadrotor import table_i_vehicles
from ilcdob.validation.nonlinear import (NonlinearReproduction, NonlinearSettings, fly_loop, reproduce_nonlinear,
                                         run_nonlinear_scenario)
from ilcdob.validation.reproduce import reproduce
from ilcdob.validation.scenarios import scenario
from ilcdob.validation.simulate import simulate_flight


def _acceptance_failures(res: NonlinearReproduction) -> list[str]:
    return [f"scenario {row['scenario']} {row['system']}: learning 3 / DOB {row['error_ratio']:.4f}, "
            f"spread 1-3 {100 * row['spread']:.1f} %, d est. learning 3 / DOB {row['dhat_ratio']:.3f}"
            for row in res.acceptance() if not row["passed"]]


_PROGRESS: list[tuple[int, int, str]] = []


@pytest.fixture(scope="module")
def short_run() -> NonlinearReproduction:
    """Scenarios 1 (order 1-2-3) and 4 (order 1-3-2) shortened to 30 s, fleet models as given."""
    scs = [dataclasses.replace(scenario(1), duration=30.0), dataclasses.replace(scenario(4), duration=30.0)]
    _PROGRESS.clear()
    return reproduce_nonlinear(ilcdob.default_fleet(), iterations=3, settings=NonlinearSettings(identify=False),
                               progress=lambda done, total, what: _PROGRESS.append((done, total, what)),
                               scenarios=scs)


def test_short_run_meets_the_acceptance(short_run):
    assert _acceptance_failures(short_run) == []


def test_short_run_chain_and_schema(short_run, fleet):
    assert [sr.order for sr in short_run.scenarios] == [["UAV1", "UAV2", "UAV3"], ["UAV1", "UAV3", "UAV2"]]
    assert short_run.scenarios[1].chain[:3] == [("UAV1", "UAV3"), ("UAV3", "UAV2"), ("UAV2", "UAV1")]
    data = short_run.to_dict()
    assert data["plant"] == "nonlinear"
    linear = reproduce(fleet, [1], 1, progress=lambda *args: None).to_dict()
    assert set(data) == set(linear)
    assert set(data["scenarios"][0]) == set(linear["scenarios"][0])
    assert set(data["scenarios"][0]["systems"]["UAV1"]) == set(linear["scenarios"][0]["systems"]["UAV1"])
    json.dumps(data)  # plain JSON types only


def test_short_run_reports_progress_per_scenario_and_writes_nothing(short_run, tmp_path, monkeypatch, capsys):
    assert [(d, n) for d, n, _ in _PROGRESS] == [(1, 2), (2, 2)]
    assert _PROGRESS[0][2].startswith("scenario 1 (") and _PROGRESS[1][2].startswith("scenario 4 (")
    # the fleet file of the models is returned, not written: it loads back to the fleet flown
    path = tmp_path / "identified_fleet.toml"
    path.write_text(short_run.identified_toml)
    assert ilcdob.load_fleet(path).systems == short_run.fleet.systems
    # default: silent, and nothing appears in the working directory
    monkeypatch.chdir(tmp_path)
    sc = dataclasses.replace(scenario(3), duration=2.0)
    reproduce_nonlinear(ilcdob.default_fleet(), iterations=1, settings=NonlinearSettings(identify=False),
                        scenarios=[sc])
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["identified_fleet.toml"]


def test_files_add_the_fleet_file_of_the_models(short_run):
    files = short_run.files()
    assert list(files)[-2:] == ["identified_fleet.toml", "results.json"]  # results.json stays last
    assert files["identified_fleet.toml"] == short_run.identified_toml
    assert "README.md" in files and "ilcdob.design.filters.band" in files["README.md"]
    assert "ilcdob.design.maps.flown" in files["README.md"]


def test_learning_flights_keep_the_true_and_measured_signals_apart(short_run):
    fl = short_run.scenarios[0].systems["UAV2"].learning[2]
    assert fl.rmse == pytest.approx(np.sqrt(np.mean((fl.r - fl.y) ** 2)))
    noise = fl.y_meas - fl.y
    assert np.std(noise) == pytest.approx(short_run.settings.sensor_noise_std, rel=0.1)
    assert fl.saturated == 0
    assert np.max(np.abs(fl.d_f)) < 5.0  # m/s^2: the learning signal stays physical


@pytest.mark.slow
def test_full_run_with_identification_meets_the_acceptance():
    calls = []
    res = reproduce_nonlinear(progress=lambda done, total, what: calls.append((done, total, what)))
    assert [(d, n) for d, n, _ in calls] == [(i, 7) for i in range(1, 8)]  # 3 vehicles, then 4 scenarios
    assert calls[0][2].startswith("identified UAV1: fit")
    assert set(res.identification) == {"UAV1", "UAV2", "UAV3"}
    assert all(v.estimate.fit_validation > 95.0 for v in res.identification.values())
    assert _acceptance_failures(res) == []


# ------------------------------------------------------------------ building blocks
def test_hover_without_wind_stays_at_rest(fleet):
    lp = fleet.loop("UAV1")
    fl = fly_loop(table_i_vehicles()["UAV1"], lp, np.zeros(500), lambda t: np.zeros_like(t))
    assert np.max(np.abs(fl.e)) < 1e-9
    assert np.max(np.abs(fl.d_hat)) < 1e-6


def test_dob_flight_is_close_to_the_linear_loop_of_its_model(fleet):
    """Small wind: the nonlinear vehicle behaves like its identified model (fit ~96-98 %)."""
    lp = fleet.loop("UAV3")
    t = np.arange(1500) * fleet.sample_time
    wind = lambda tt: 0.5 * np.sin(0.9425 * tt)  # noqa: E731
    nl = fly_loop(table_i_vehicles()["UAV3"], lp, np.zeros(t.size), wind)
    lin = simulate_flight(lp, np.zeros(t.size), wind(t), mode="dob")
    assert nl.rmse == pytest.approx(lin.rmse, rel=0.1)
    assert np.sqrt(np.mean((nl.y - lin.y) ** 2)) < 0.15 * lin.rmse


def test_scenario_run_rejects_fleets_without_vehicles(fleet_file):
    fleet = ilcdob.load_fleet(fleet_file())  # systems "A" and "B"
    with pytest.raises(SpecError, match=r"system\(s\) \['A', 'B'\] have no nonlinear vehicle"):
        run_nonlinear_scenario(fleet, None, scenario(1))
    with pytest.raises(SpecError, match="no nonlinear vehicle"):
        reproduce_nonlinear(fleet, [1])


# ------------------------------------------------------------------ bad inputs
@pytest.mark.parametrize("kwargs, match", [
    ({"sensor_noise_std": -0.001}, "sensor_noise_std"),
    ({"sensor_noise_std": 0.5}, "sensor_noise_std"),
    ({"seed": -1}, "seed"),
    ({"identify": "yes"}, "identify"),
    ({"bandwidth": 0.0}, "bandwidth"),
    ({"bandwidth": float("nan")}, "bandwidth"),
    ({"bandwidth": "wide"}, "bandwidth"),
    ({"learning_gain": 0.0}, "learning_gain"),
    ({"learning_gain": 1.5}, "learning_gain"),
    ({"airframe_disturbance": 1}, "airframe_disturbance"),
    ({"inner_rate_hz": 10.0}, "inner_rate_hz"),
])
def test_settings_reject_bad_values(kwargs, match):
    with pytest.raises(SpecError, match=match):
        NonlinearSettings(**kwargs)


def test_fly_loop_rejects_bad_inputs(fleet):
    v = table_i_vehicles()["UAV1"]
    lp = fleet.loop("UAV1")
    r = np.zeros(50)
    calm = lambda t: np.zeros_like(t)  # noqa: E731
    with pytest.raises(SpecError, match="`mode`"):
        fly_loop(v, lp, r, calm, mode="pid")
    with pytest.raises(SpecError, match="`vehicle`"):
        fly_loop("UAV1", lp, r, calm)
    with pytest.raises(SpecError, match="`loop`"):
        fly_loop(v, fleet, r, calm)
    with pytest.raises(SpecError, match="`disturbance`: got ndarray"):
        fly_loop(v, lp, r, np.zeros(50))
    with pytest.raises(SpecError, match="`d_f`"):
        fly_loop(v, lp, r, calm, d_f=np.ones(50), mode="no_dob")
    with pytest.raises(SpecError, match="`rng`"):
        fly_loop(v, lp, r, calm, noise_std=0.001)
    with pytest.raises(SpecError, match="`noise_std`"):
        fly_loop(v, lp, r, calm, noise_std=-1.0)
    with pytest.raises(SpecError, match="inner_rate_hz"):
        fly_loop(dataclasses.replace(v, inner_rate_hz=130.0), lp, r, calm)
    with pytest.raises(ilcdob.SignalError, match="`d_f`"):
        fly_loop(v, lp, r, calm, d_f=np.ones(49))


def test_reproduce_rejects_bad_arguments():
    with pytest.raises(SpecError, match="`iterations`"):
        reproduce_nonlinear(iterations=0)
    with pytest.raises(SpecError, match="`settings`"):
        reproduce_nonlinear(settings={"seed": 1})
    with pytest.raises(SpecError, match="`fleet`"):
        reproduce_nonlinear(fleet="fleet.toml")


@pytest.mark.slow  # 8 s (-m slow); the nonlinear reproduction's acceptance runs by default in this module
def test_cli_reproduce_nonlinear_writes_the_schema(tmp_path):
    out = tmp_path / "nl"
    assert main(["reproduce", "--plant", "nonlinear", "--scenarios", "3", "--iterations", "1", "--no-figures",
                 "--out", str(out)]) == 0
    data = json.loads((out / "results.json").read_text())
    assert data["plant"] == "nonlinear"
    assert data["fleet"] == "identified_fleet.toml"
    assert ilcdob.load_fleet(out / "identified_fleet.toml").names == ["UAV1", "UAV2", "UAV3"]
    assert "**Plant: nonlinear.**" in (out / "README.md").read_text()


def test_cli_plant_option(tmp_path, capsys):
    assert main(["reproduce", "--plant", "quadrotor", "--out", str(tmp_path)]) == 2
    assert "invalid choice: 'quadrotor'" in capsys.readouterr().err
    assert main(["reproduce", "--plant", "nonlinear", "--seed", "-3", "--out", str(tmp_path)]) == 2
    assert "`seed`: got -3" in capsys.readouterr().err


def test_a_given_order_is_flown_on_the_nonlinear_vehicles():
    sc = dataclasses.replace(scenario(1), duration=4.0)
    order = ["UAV2", "UAV1", "UAV3"]
    res = reproduce_nonlinear(ilcdob.default_fleet(), iterations=1, settings=NonlinearSettings(identify=False),
                              scenarios=[sc, dataclasses.replace(scenario(4), duration=4.0)], order=order)
    for sr in res.scenarios:
        assert sr.order == order and list(sr.systems) == order
        assert sr.chain == [("UAV2", "UAV1"), ("UAV1", "UAV3"), ("UAV3", "UAV2")]
    one = run_nonlinear_scenario(ilcdob.default_fleet(), None, sc, 1, settings=NonlinearSettings(identify=False),
                                 order=["UAV3", "UAV2"])
    assert one.order == ["UAV3", "UAV2"] and one.chain == [("UAV3", "UAV2"), ("UAV2", "UAV3")]


def test_a_bad_order_fails_before_any_flight():
    # checked against the fleet before the vehicles are identified (which takes seconds)
    with pytest.raises(SpecError, match=r"`order`: unknown system\(s\) 'UAV7'"):
        reproduce_nonlinear(order=["UAV1", "UAV7"])
    with pytest.raises(SpecError, match=r"`order`: 'UAV2' given more than once"):
        reproduce_nonlinear(order=["UAV2", "UAV2"])
