"""Fleet files: the schema of ilcdob/fleet.py, and clear errors for bad files."""

from __future__ import annotations

import tomllib

import pytest

import ilcdob
from ilcdob import FleetError


def test_default_fleet_is_the_papers_three_uavs(fleet):
    assert fleet.names == ["UAV1", "UAV2", "UAV3"]
    assert fleet.sample_time == 0.02
    # Table I outer-loop proportional gains (paper)
    assert [s.controller.kp for s in fleet.systems] == [3.0, 1.2, 1.9]
    for lp in fleet.loops:
        assert max(abs(lp.poles())) < 1


def test_issue_schema_loads(fleet_file):
    f = ilcdob.load_fleet(fleet_file())
    assert f.names == ["A", "B"]
    assert f.systems[0].plant.den == (0.1, 1.0, 0.0, 0.0)
    assert f.systems[1].plant.delay == 0.0


@pytest.mark.parametrize(
    "old, new, must_name",
    [
        ('dob = { q_order = 3, q_time_constant = 0.15 }\n\n', "\n", ["'A'", "dob"]),
        ("kd = 2.4,", "kd = 2.4, kx = 1.0,", ["'A'", "controller", "kx"]),
        ("q_order = 3, q_time_constant = 0.15 }\n\n", "q_order = 3, q_time_constant = 0.0 }\n\n",
         ["'A'", "q_time_constant", "0.0"]),
        ("q_order = 3, q_time_constant = 0.15 }\n\n", "q_order = 2, q_time_constant = 0.15 }\n\n",
         ["'A'", "q_order", "improper"]),
        ("derivative_filter = 0.05 }\ndob = { q_order = 3, q_time_constant = 0.15 }\n\n",
         "derivative_filter = -0.05 }\ndob = { q_order = 3, q_time_constant = 0.15 }\n\n",
         ["'A'", "derivative_filter"]),
        ("kp = 3.0, ki = 0.3, kd = 2.4", "kp = 300.0, ki = 0.3, kd = 0.1", ["'A'", "unstable", "controller"]),
        ("delay = 0.0\n", "delay = -0.1\n", ["'A'", "delay", "-0.1"]),
        ("sample_time = 0.02", "sample_time = 0", ["sample_time"]),
        ('name = "B"', 'name = "A"', ["duplicated", "'A'"]),
        ("[[system]]\nname = \"B\"", "colour = 1\n[[system]]\nname = \"B\"", ["'A'", "colour"]),
    ],
)
def test_bad_fleet_files_name_file_system_and_key(fleet_file, good_fleet_text, old, new, must_name):
    assert old in good_fleet_text
    path = fleet_file(good_fleet_text.replace(old, new, 1))
    with pytest.raises(FleetError) as info:
        ilcdob.load_fleet(path)
    msg = str(info.value)
    assert str(path) in msg
    for part in must_name:
        assert part in msg, msg


@pytest.mark.parametrize("value", ["1e-7", "5e-5", "2.0", "20", "1e300", "1e-300"])
def test_sample_times_outside_the_stated_range_are_refused(fleet_file, good_fleet_text, value):
    # 1e-7 s would make a 60 s scenario 600 million samples a flight; 20 is ms written as s
    path = fleet_file(good_fleet_text.replace("sample_time = 0.02", f"sample_time = {value}"))
    with pytest.raises(FleetError) as info:
        ilcdob.load_fleet(path)
    msg = str(info.value)
    assert str(path) in msg and "`sample_time`" in msg and f"got {tomllib.loads(f'v = {value}')['v']!r}" in msg
    assert "0.0001 to 1 s" in msg


@pytest.mark.parametrize("value", ["1e-4", "0.001", "0.05"])
def test_sample_times_inside_the_range_load(fleet_file, good_fleet_text, value):
    path = fleet_file(good_fleet_text.replace("sample_time = 0.02", f"sample_time = {value}"))
    assert ilcdob.load_fleet(path).sample_time == float(value)


def test_unreadable_and_invalid_toml(fleet_file, tmp_path):
    with pytest.raises(FleetError, match="cannot read"):
        ilcdob.load_fleet(tmp_path / "missing.toml")
    with pytest.raises(FleetError, match="not valid TOML"):
        ilcdob.load_fleet(fleet_file("sample_time = = 1"))


def test_fleet_errors_are_value_errors():
    assert issubclass(FleetError, ValueError) and issubclass(FleetError, ilcdob.IlcdobError)


def test_uncertainty_bound_in_the_fleet_file_defines_the_delta_set(tmp_path):
    import numpy as np

    from ilcdob.design import delta_set
    from ilcdob.fleet import DEFAULT_FLEET_PATH, load_fleet

    text = DEFAULT_FLEET_PATH.read_text().replace('name = "UAV2"', 'name = "UAV2"\nuncertainty = { bound = 0.25 }', 1)
    path = tmp_path / "fleet.toml"
    path.write_text(text)
    fleet = load_fleet(path)
    spec = next(s for s in fleet.systems if s.name == "UAV2")
    assert spec.uncertainty.bound == 0.25
    ds = delta_set(spec, fleet.sample_time, 6, np.random.default_rng(1))
    # the stated (continuous) bound's radius on the sampled plant: 0.25 at low frequency, above it towards
    # Nyquist through the hold's aliases (at most 0.2 % for this plant at 50 Hz); every sample inside it
    assert ds.source == "fleet bound" and ds.bound[0] == pytest.approx(0.25, rel=1e-9)
    assert np.all(ds.bound >= 0.25) and np.max(ds.bound) < 0.2505
    assert np.all(np.abs(ds.deltas()) <= ds.bound + 1e-9)
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("bound = 0.25", "bound = 1.5"))
    with pytest.raises(FleetError, match=r"UAV2.*uncertainty.*bound"):
        load_fleet(bad)
