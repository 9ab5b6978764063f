"""The paper's scenarios on rotorpy's own SE3 controller (ilcdob.validation.channel_reproduction) and its command."""

from __future__ import annotations

import json

import pytest

from ilcdob.errors import SpecError
from ilcdob.validation.channel_reproduction import DEFAULT_VEHICLES, ChannelSettings, ChannelVehicle, reproduce_channels


def test_bad_settings_and_command_lines_name_what_is_wrong(tmp_path):
    from ilcdob.app.commands import reproduce_to_folder

    with pytest.raises(SpecError, match="`vehicles`: got"):
        ChannelSettings(vehicles=DEFAULT_VEHICLES[:1])
    with pytest.raises(SpecError, match="names \\['a', 'a'\\] repeat"):
        ChannelSettings(vehicles=(ChannelVehicle("a", "hummingbird"), ChannelVehicle("a", "crazyflie")))
    with pytest.raises(SpecError, match="`channels`: got 'thrust'"):
        ChannelSettings(channels=("thrust",))
    with pytest.raises(SpecError, match="`trial_s`: got -1"):
        ChannelSettings(trial_s=-1)
    with pytest.raises(SpecError, match="`--controller own`: needs --plant rotorpy"):
        reproduce_to_folder(tmp_path / "out", controller="own")
    with pytest.raises(SpecError, match="`--controller own` takes no --order"):
        reproduce_to_folder(tmp_path / "out", plant="rotorpy", controller="own", order=["a", "b"])
    with pytest.raises(SpecError, match="`--controller`: got 'px4'"):
        reproduce_to_folder(tmp_path / "out", controller="px4")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_short_run_writes_its_tables_and_meets_the_acceptance():
    """Two vehicles (rotorpy's hummingbird and an airframe of our own), the acceleration channel, hover, one
    iteration, 8 s trials: every acceptance row is met, and results.json holds what README.md tabulates."""
    pytest.importorskip("rotorpy")
    settings = ChannelSettings(vehicles=DEFAULT_VEHICLES[::2], channels=("acceleration",), trial_s=8.0,
                               identification_s=10.0)
    res = reproduce_channels([1], 1, settings)
    files = res.files(figures=True)
    data = json.loads(files["results.json"])
    assert data["controller"] == "own" and len(data["runs"]) == 3
    assert all(row["passed"] for row in data["acceptance"]), data["acceptance"]
    paper = next(r for r in data["runs"] if r["disturbance"] == "paper")
    assert f"{paper['ratios']['lab-quad'][0]:.4f}" in files["README.md"]
    assert files["learning.png"][:8] == b"\x89PNG\r\n\x1a\n"
