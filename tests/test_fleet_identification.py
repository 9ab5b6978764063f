"""Acceptance: each built-in vehicle is identified from its synthetic step and chirp flights
with held-out fit above 95 %, and the identified fleet file loads."""

from __future__ import annotations

import numpy as np
import pytest

import ilcdob
from ilcdob.app.cli import main
from ilcdob.identification.fleet_id import segments
from ilcdob.signals import FlightData


def test_identify_fleet_cli_fits_every_vehicle(tmp_path, capsys):
    out = tmp_path / "id"
    assert main(["identify-fleet", "--out", str(out)]) == 0
    fleet = ilcdob.load_fleet(out / "identified_fleet.toml")
    derived_tau = {"UAV1": 0.100, "UAV2": 0.1053, "UAV3": 0.1395}  # tuned into the nonlinear vehicles
    for spec in fleet.systems:
        ident = spec.identification
        assert ident.fit_validation > 95.0, (spec.name, ident.fit_validation)
        assert 1.0 / spec.plant.den[1] == pytest.approx(derived_tau[spec.name], rel=0.05)
        assert spec.plant.num[0] / spec.plant.den[1] == pytest.approx(1.0, rel=0.02)  # unit acceleration gain
        for name in ("steps.csv", "chirp.parquet", "model.json", "bode.png"):
            assert (out / spec.name / name).exists()


def test_segments_cover_the_flight_once():
    fd = FlightData(np.arange(1501) * 0.02, {"x": np.arange(1501.0)})
    parts = segments([fd], 10.0)
    assert [len(p) for p in parts] == [500, 500, 501]
    assert np.array_equal(np.concatenate([p["x"] for p in parts]), fd["x"])
