"""The paper's scenarios on rotorpy's own SE3 controller (ilcdob.validation.channel_reproduction) and its command."""

from __future__ import annotations

import json

import numpy as np
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
                               identification_s=10.0, identified_axes=())
    res = reproduce_channels([1], 1, settings)
    files = res.files(figures=True)
    data = json.loads(files["results.json"])
    assert data["controller"] == "own" and len(data["runs"]) == 3
    assert all(row["passed"] for row in data["acceptance"]), data["acceptance"]
    paper = next(r for r in data["runs"] if r["disturbance"] == "paper")
    assert f"{paper['ratios']['lab-quad'][0]:.4f}" in files["README.md"]
    assert files["learning.png"][:8] == b"\x89PNG\r\n\x1a\n"


_VEHICLES_FILE = """
description = "two airframes of a lab"
[[vehicle]]
name = "heavy"
airframe = "hummingbird"
params = { mass = 2.0, Ixx = 0.03, Iyy = 0.03, Izz = 0.05 }
position_gains = { kp = [3.0, 3.0, 8.0], kd = [2.6, 2.6, 6.0] }

[[vehicle]]
name = "crazyflie"
"""


def test_a_vehicles_file_gives_the_labs_airframes(tmp_path):
    """`--vehicles FILE`: each vehicle's complete rotorpy set is its starting set changed by `params` (the rest
    rotorpy's own values), its gains as given; bad tables name the file, the vehicle and the key."""
    pytest.importorskip("rotorpy")
    from ilcdob.app.commands import reproduce_to_folder
    from ilcdob.validation.channel_reproduction import load_vehicles
    from ilcdob.vehicles.rotorpy_vehicle import shipped_airframe

    path = tmp_path / "v.toml"
    path.write_text(_VEHICLES_FILE)
    heavy, cf = load_vehicles(path)
    base = shipped_airframe("hummingbird")
    changed = {"mass": 2.0, "Ixx": 0.03, "Iyy": 0.03, "Izz": 0.05}
    assert set(heavy.airframe) == set(base)
    for key, value in heavy.airframe.items():
        np.testing.assert_equal(value, changed.get(key, base[key]), err_msg=key)
    assert heavy.position_gains == ((3.0, 3.0, 8.0), (2.6, 2.6, 6.0))
    np.testing.assert_equal(cf.airframe, shipped_airframe("crazyflie"))
    assert cf.position_gains is None
    for text, match in (('[[vehicle]]\nname = "x"', "key `airframe`: got 'x'"),
                        ('[[vehicle]]\nname = "a"\nairframe = "hummingbird"\nparams = { massa = 1.0 }',
                         "vehicle 'a', key `params`: .*\\['massa'\\] are not rotorpy parameters"),
                        ('[[vehicle]]\nname = "a"\nairframe = "hummingbird"\nposition_gains = { kp = [1, 2], '
                         'kd = [1, 1, 1] }', "key `position_gains.kp`: got \\[1, 2\\]"),
                        ('[[vehicle]]\nname = "a"\ncolour = "red"', "unknown key\\(s\\) \\['colour'\\]"),
                        ('fleet = 1', "expected \\[\\[vehicle\\]\\] tables")):
        path.write_text(text)
        with pytest.raises(SpecError, match=match):
            load_vehicles(path)
    with pytest.raises(SpecError, match="`--vehicles`: .*the linear and nonlinear plants fly a fleet"):
        reproduce_to_folder(tmp_path / "out", vehicles=path)
    assert not (tmp_path / "out").exists()
