"""Acceptance: each built-in vehicle is identified from its synthetic step and chirp flights
with held-out fit above 95 %, and the identified fleet file loads; the library writes nothing
and returns every output file as content (:meth:`FleetIdentification.files`)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

import ilcdob
from ilcdob.app.cli import main
from ilcdob.fleet import fleet_from_dict
from ilcdob.identification.fleet_id import (IDENTIFICATION_SOURCE, FleetIdentification, identified_systems,
                                            identify_fleet, segments)
from ilcdob.signals import FlightData

DERIVED_TAU = {"UAV1": 0.100, "UAV2": 0.1053, "UAV3": 0.1395}  # tuned into the nonlinear vehicles
EXPERIMENTS = ("steps", "chirp", "steps-validation", "chirp-validation")
_PROGRESS: list[tuple[int, int, str]] = []


@pytest.fixture(scope="module")
def identified() -> FleetIdentification:
    _PROGRESS.clear()
    return identify_fleet(ilcdob.default_fleet(), progress=lambda done, total, what: _PROGRESS.append(
        (done, total, what)))


def _check_identified_fleet(fleet: ilcdob.Fleet) -> None:
    for spec in fleet.systems:
        ident = spec.identification
        assert ident.fit_validation > 95.0, (spec.name, ident.fit_validation)
        assert ident.source == IDENTIFICATION_SOURCE
        assert 1.0 / spec.plant.den[1] == pytest.approx(DERIVED_TAU[spec.name], rel=0.05)
        assert spec.plant.num[0] / spec.plant.den[1] == pytest.approx(1.0, rel=0.02)  # unit acceleration gain


def test_identify_fleet_fits_every_vehicle(identified):
    assert list(identified.results) == ["UAV1", "UAV2", "UAV3"]
    assert all(v.estimate.fit_validation > 95.0 for v in identified.results.values())
    fleet = fleet_from_dict(tomllib.loads(identified.identified_toml), "identified_fleet.toml")
    _check_identified_fleet(fleet)
    for spec in fleet.systems:  # the file carries the estimates exactly (repr of every float)
        est = identified.results[spec.name].estimate
        assert spec.plant.num == tuple(est.num) and spec.plant.den == tuple(est.den)
        assert spec.identification.parameters == tuple(est.theta)
    base = ilcdob.default_fleet()
    assert [s.controller for s in fleet.systems] == [s.controller for s in base.systems]
    assert [s.noise for s in fleet.systems] == [s.noise for s in base.systems]


def test_identify_fleet_reports_progress_per_vehicle(identified):
    assert [(d, n) for d, n, _ in _PROGRESS] == [(1, 3), (2, 3), (3, 3)]
    assert _PROGRESS[0][2].startswith("UAV1: fit ") and "(validation)" in _PROGRESS[0][2]


def test_identify_fleet_is_silent_and_writes_nothing(tmp_path, monkeypatch, capsys):
    fleet = ilcdob.default_fleet()
    monkeypatch.chdir(tmp_path)
    one = fleet_from_dict({"sample_time": fleet.sample_time, "system": [
        {"name": "UAV2", "plant": {"num": list(fleet.systems[1].plant.num), "den": list(fleet.systems[1].plant.den)},
         "controller": {"kp": 1.2, "ki": 0.12, "kd": 1.53, "derivative_filter": 0.05},
         "dob": {"q_order": 3, "q_time_constant": 0.15}}]}, "one.toml")
    res = identify_fleet(one, seed=4)
    assert list(res.results) == ["UAV2"] and res.seed == 4
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert list(tmp_path.iterdir()) == []


def test_files_name_every_output_with_its_content(identified, tmp_path):
    files = identified.files(figures=False)
    expected = {"identified_fleet.toml"}
    for name in ("UAV1", "UAV2", "UAV3"):
        expected |= {f"{name}/{stem}.{ext}" for stem in EXPERIMENTS for ext in ("csv", "parquet")}
        expected.add(f"{name}/model.json")
    assert set(files) == expected
    assert files["identified_fleet.toml"] == identified.identified_toml
    assert files["UAV2/model.json"] == identified.results["UAV2"].estimate.to_dict()
    # flights: the FlightData writers, called with the destination path by the application
    flight = identified.results["UAV3"].validation[1]
    files["UAV3/chirp-validation.csv"](tmp_path / "c.csv")
    files["UAV3/chirp-validation.parquet"](tmp_path / "c.parquet")
    flight.to_csv(tmp_path / "ref.csv")
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "ref.csv").read_bytes()
    assert (tmp_path / "c.parquet").stat().st_size > 0


def test_files_with_figures_are_matplotlib_figures(identified):
    from matplotlib.figure import Figure

    files = identified.files()
    for name in ("UAV1", "UAV2", "UAV3"):
        for fig in ("compare.png", "residuals.png", "bode.png"):
            assert isinstance(files[f"{name}/{fig}"], Figure)


def test_identified_systems_keep_unidentified_systems(identified, fleet):
    partial = {"UAV2": identified.results["UAV2"]}
    systems = identified_systems(fleet, partial)
    assert systems[0] == fleet.systems[0] and systems[2] == fleet.systems[2]
    assert systems[1].plant.num == tuple(identified.results["UAV2"].estimate.num) and systems[1].model is None
    assert systems[1].controller == fleet.systems[1].controller


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
def test_identify_fleet_cli_fits_every_vehicle(tmp_path, capsys):
    out = tmp_path / "id"
    assert main(["identify-fleet", "--out", str(out)]) == 0
    fleet = ilcdob.load_fleet(out / "identified_fleet.toml")
    _check_identified_fleet(fleet)
    for spec in fleet.systems:
        for name in ("steps.csv", "chirp.parquet", "model.json", "bode.png"):
            assert (out / spec.name / name).exists()


def test_segments_cover_the_flight_once():
    fd = FlightData(np.arange(1501) * 0.02, {"x": np.arange(1501.0)})
    parts = segments([fd], 10.0)
    assert [len(p) for p in parts] == [500, 500, 501]
    assert np.array_equal(np.concatenate([p["x"] for p in parts]), fd["x"])
