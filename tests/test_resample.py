"""Resampling a log to another rate: anti-aliased, on identify and learn, and named where a rate does not match.

The truth of the anti-aliasing is the signal itself: a 0.5 Hz sine with a 100 Hz component logged at 250 Hz,
resampled to 50 Hz (Nyquist 25 Hz), must be the 0.5 Hz sine alone; taking every fifth sample instead aliases the
100 Hz component onto 0 Hz (100 = 2 x 50), a constant error of its amplitude times the sine of its phase.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.errors import SpecError
from ilcdob.signals import FlightData
from ilcdob.validation.simulate import simulate_flight


def _record(ts: float = 0.004, n: int = 2500) -> tuple[FlightData, np.ndarray]:
    t = np.arange(n) * ts
    slow = np.sin(2 * np.pi * 0.5 * t)
    return FlightData(t, {"x": slow + 0.3 * np.sin(2 * np.pi * 100 * t + 1.0)}, {"x": "m"}), slow


def test_resampling_removes_what_lies_above_the_new_nyquist():
    fd, _ = _record()
    r = fd.resampled(0.02)
    slow = np.sin(2 * np.pi * 0.5 * r.t)
    assert r.ts == pytest.approx(0.02) and len(r) == 500 and r.metadata["rate_change"]["down"] == 5
    # measured: 3.2e-3 from the fifth sample in (the Kaiser FIR's ripple); 0.14 on the first sample, where the line
    # continuing the record carries the 100 Hz part's 0.25 (no filter knows a signal before its first sample)
    assert np.max(np.abs(r["x"] - slow)[5:-5]) < 5e-3 and np.max(np.abs(r["x"] - slow)) < 0.3
    naive = fd["x"][::5] - np.sin(2 * np.pi * 0.5 * fd.t[::5])
    assert np.min(np.abs(naive)) > 0.25  # the alias: 0.3 sin(1) = 0.252 on every sample


def test_rational_and_unusable_ratios():
    fd, _ = _record()
    up = fd.resampled(0.006)  # 2 / 3
    assert (up.metadata["rate_change"]["up"], up.metadata["rate_change"]["down"]) == (2, 3)
    assert fd.resampled(0.004) is fd
    with pytest.raises(SpecError, match=r"`--resample`: .*no ratio of integers"):
        fd.resampled(0.004 * 1.0001234567)  # 1 / 1.0001234567: no fraction of denominators <= 1000 within 1e-6
    with pytest.raises(SpecError, match=r"`--resample`: got -0.1"):
        fd.resampled(-0.1)


def test_identify_resamples_and_says_so(tmp_path, capsys):
    """A 100 Hz log of ``4 / (s^2 + 2.8 s + 4)`` fitted at 50 Hz: the model's sample time is the new one, the
    file records the resampling and the fit still finds the plant within 3 % (measured 1.4 % on a0: the input was
    held every 10 ms, the fit holds it every 20 ms, half a new sample of apparent lead)."""
    from ilcdob.identification.oe import simulate_zoh
    from ilcdob.uncertainty import ModelStructure

    st = ModelStructure(2, 0, 0)
    theta = st.join([4.0], [1.0, 2.8, 4.0])
    t = np.arange(6000) * 0.01
    u = np.sin(2 * np.pi * 0.2 * t) + 0.5 * np.sin(2 * np.pi * 0.9 * t)  # smooth: resampling keeps it
    y = simulate_zoh(st, theta, u, 0.01)
    FlightData(t, {"u": u, "y": y}, {"u": "m/s^2", "y": "m"}).to_csv(tmp_path / "log.csv")
    assert main(["identify", str(tmp_path / "log.csv"), "--input", "u", "--output", "y", "--poles", "2",
                 "--resample", "0.02", "--out", str(tmp_path / "m.json")]) == 0
    assert "--resample 0.02 s: files logged every 0.01 s resampled" in capsys.readouterr().err
    model = json.loads((tmp_path / "m.json").read_text())
    assert model["resampled_to_s"] == 0.02 and model["sample_time"] == pytest.approx(0.02)
    np.testing.assert_allclose(model["den"], [1.0, 2.8, 4.0], rtol=0.03)


def test_learn_names_the_rate_and_resamples_a_trial(fleet, tmp_path, capsys):
    """A trial logged at 100 Hz against the fleet's 50 Hz design: refused with the option that helps; with
    ``--resample 0.02`` learned."""
    n = 1500
    t50 = np.arange(n) * fleet.sample_time
    fl = simulate_flight(fleet.loop("UAV1"), np.zeros(n), np.sin(0.9425 * t50))
    t100 = np.arange(2 * n - 1) * 0.01
    e100 = np.interp(t100, t50, fl.e)
    FlightData(t100, {"error": e100}, {"error": "m"}).to_csv(tmp_path / "trial.csv")
    args = ["learn", str(tmp_path / "trial.csv"), "--from", "UAV1", "--to", "UAV2", "--error", "error", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "no")]) == 2
    assert "differs from the fleet's 0.02 s; resample the trial to the fleet's rate (--resample 0.02)" in \
        capsys.readouterr().err
    assert main([*args, "--resample", "0.02", "--out", str(tmp_path / "yes")]) == 0
    assert json.loads((tmp_path / "yes" / "learning.json").read_text())["trial"]["samples"] == n
