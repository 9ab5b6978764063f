"""A learning signal a vehicle can fly: acceleration limits (ilcdob.specs.LimitSpec, ilcdob.design.law.limit)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import ilcdob
from ilcdob.design.law.limit import LearningLimitWarning, enforce_limit
from ilcdob.errors import FleetError, LearningLimitError, SpecError
from ilcdob.specs import GRAVITY, LimitSpec, SensorSpec


def test_limits_from_tilt_thrust_and_stated_acceleration():
    # a tilted thrust that holds the altitude: horizontal g tan(tilt); a thrust margin k: g sqrt(k^2 - 1)
    assert LimitSpec(tilt=35.0).max_acceleration == pytest.approx(9.80665 * math.tan(math.radians(35.0)), rel=1e-12)
    assert LimitSpec(thrust_to_weight=2.0).max_acceleration == pytest.approx(9.80665 * math.sqrt(3.0), rel=1e-12)
    both = LimitSpec(tilt=35.0, thrust_to_weight=1.2, acceleration=8.0)
    assert both.max_acceleration == pytest.approx(GRAVITY * math.sqrt(1.2 ** 2 - 1), rel=1e-12)  # the smallest
    assert "tilt 35 deg" in both.describe() and "thrust/weight 1.2" in both.describe()


@pytest.mark.parametrize("kwargs, match", [({}, "at least one"), ({"tilt": 90.0}, "limits.tilt"),
                                           ({"tilt": -5}, "limits.tilt"), ({"thrust_to_weight": 1.0}, "ratio > 1"),
                                           ({"acceleration": 0.0}, "limits.acceleration"),
                                           ({"tilt": "steep"}, "limits.tilt")])
def test_bad_limits_are_refused(kwargs, match):
    with pytest.raises(SpecError, match=match):
        LimitSpec(**kwargs)
    with pytest.raises(SpecError, match="sensor.noise_std"):
        SensorSpec(noise_std=-1e-3)


def test_fleet_files_carry_limits_and_sensor_noise(fleet_file, good_fleet_text):
    text = good_fleet_text.replace('dob = { q_order = 3, q_time_constant = 0.15 }\n\n[[system]]',
                                   'dob = { q_order = 3, q_time_constant = 0.15 }\nlimits = { tilt = 35.0 }\n'
                                   'sensor = { noise_std = 0.0005 }\n\n[[system]]', 1)
    flt = ilcdob.load_fleet(fleet_file(text))
    a = flt.systems[0]
    assert a.limits == LimitSpec(tilt=35.0) and a.sensor == SensorSpec(5e-4) and flt.systems[1].limits is None
    again = ilcdob.load_fleet(fleet_file(ilcdob.fleet_to_toml(flt.sample_time, flt.systems), "again.toml"))
    assert again.systems[0].limits == a.limits and again.systems[0].sensor == a.sensor
    with pytest.raises(FleetError, match=r"system 'A', key `limits`: .*limits.tilt"):
        ilcdob.load_fleet(fleet_file(text.replace("tilt = 35.0", "tilt = 95.0"), "bad.toml"))
    with pytest.raises(FleetError, match="unknown key.*angle"):
        ilcdob.load_fleet(fleet_file(text.replace("tilt = 35.0", "angle = 35.0"), "bad2.toml"))


def test_a_signal_within_the_limit_passes_unchanged():
    d = np.array([0.5, -1.0, 2.0])
    out, report = enforce_limit(d, LimitSpec(acceleration=3.0))
    np.testing.assert_array_equal(out, d)
    assert report.peak == 2.0 and report.beyond == 0 and not report.clipped
    assert enforce_limit(d, None) == (pytest.approx(d), None)


def test_a_signal_beyond_the_limit_is_clipped_with_a_warning_naming_peak_limit_and_cause():
    d = np.array([0.5, -9.0, 12.0, 1.0])
    with pytest.warns(LearningLimitWarning, match=r"peaks at 12 m/s\^2.*6.87 m/s\^2 \(tilt 35 deg\) on 2 of 4 "
                                                   r"samples.*sensor noise through the plant inverse.*band 10 rad/s"):
        out, report = enforce_limit(d, LimitSpec(tilt=35.0), "clip", "learning signal of B", "10 rad/s")
    lim = LimitSpec(tilt=35.0).max_acceleration
    np.testing.assert_allclose(out, [0.5, -lim, lim, 1.0])
    assert report.clipped and report.beyond == 2 and report.peak == 12.0


def test_refuse_raises_and_unknown_policies_are_refused():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(LearningLimitError, match="refused"):
            enforce_limit(np.array([10.0]), LimitSpec(acceleration=1.0), "refuse")
    with pytest.raises(SpecError, match="on_limit.*clip.*refuse"):
        enforce_limit(np.array([1.0]), LimitSpec(acceleration=1.0), "ignore")


def test_the_unfiltered_law_on_noisy_data_hits_the_limit_and_the_band_does_not(fleet):
    """0.5 mm of position noise on UAV1's DOB-only hover, UAV2 learning: the Theorem's filters unfiltered ask
    for hundreds of m/s^2 (measured peak 260, beyond UAV2's 6.71 m/s^2 on most samples) and are clipped with a
    warning; the automatic band stays within 0.6 m/s^2 (measured 0.50, the disturbance's 0.5 m/s^2 share)."""
    from ilcdob.design.pair import design_pair
    from ilcdob.validation.scenarios import scenario
    from ilcdob.validation.simulate import simulate_flight

    sc = scenario(1)
    t = sc.time(fleet.sample_time)
    noise = np.random.default_rng(1).normal(0.0, 5e-4, t.size)
    flight = simulate_flight(fleet.loop("UAV1"), sc.reference(t), sc.disturbance(t), sensor_noise=noise)
    with pytest.warns(LearningLimitWarning, match="learning signal of UAV2 from UAV1: peaks at"):
        raw = design_pair(fleet, "UAV1", "UAV2", band="off").learning(flight.measured_error, flight.d_f)
    assert raw.limit.peak > 100.0 and raw.limit.beyond > t.size // 2 and raw.limit.clipped
    auto = design_pair(fleet, "UAV1", "UAV2").learning(flight.measured_error, flight.d_f)
    assert auto.band.cutoff is not None and auto.limit.peak <= 0.6 and not auto.limit.clipped


@pytest.mark.parametrize("where, cause", [(slice(0, 2), r"the trial's start \(all in its first 5 samples\).*--start"),
                                          (slice(-3, None), r"the trial's end \(all in its last 5 samples\).*--stop"),
                                          (slice(200, 203), r"sensor noise .*learning band 3 rad/s")])
def test_the_cause_named_is_where_the_signal_leaves_the_limit(where, cause):
    """A learning signal beyond the limit only at a trial's first samples comes from an error not at rest at
    t = 0 (a step through the plant inverse), only at its last from an error still moving when the recording
    stops; elsewhere the message keeps the noise-and-band advice."""
    d = 0.1 * np.sin(np.arange(500) * 0.05)
    d[where] = 20.0
    with pytest.warns(LearningLimitWarning, match=cause):
        enforce_limit(d, LimitSpec(acceleration=5.0), "clip", "learning signal of B", "3 rad/s")
