"""Excitation design: step sequences, chirps, the suggested band and the set-point CSV.

References: scipy.signal.chirp (an independent chirp implementation) for the waveforms,
the closed-form cycle count of a sweep for its zero crossings, the closed-form -3 dB
frequency of a discrete first-order lag for the bandwidth, and a direct evaluation of
``C (zI - A)^-1 B + D`` for the fleet's closed loops.
"""

from __future__ import annotations

import dataclasses
import math

import control as ct
import numpy as np
import pytest
from scipy import signal as sps

from ilcdob.errors import SignalError, SpecError
from ilcdob.identification.excitation import (BAND_HIGH_FACTOR, BAND_LOW_FACTOR, NYQUIST_FRACTION, Chirp,
                                              StepSequence, closed_loop_bandwidth, suggest_band,
                                              suggest_band_for_loop, write_setpoint_csv)
from ilcdob.identification.loaders import load_csv


# ----------------------------------------------------------------------------- StepSequence

def test_step_sequence_levels_ramps_and_duration():
    s = StepSequence([0.0, 1.0, -0.5], hold=2.0, ramp=0.5)
    assert s.levels == (0.0, 1.0, -0.5) and s.duration == 6.0
    t = np.array([-1.0, 0.0, 1.9, 2.0, 2.25, 2.5, 3.9, 4.0, 4.25, 5.99, 6.0, 9.0])
    want = [0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 0.25, -0.5, -0.5, -0.5]
    np.testing.assert_allclose(s.signal(t), want, atol=1e-12)
    # on a grid the largest sample-to-sample change is the ramp slope times ts
    ts = 0.01
    tg, x = s.sample(ts)
    assert tg[-1] == pytest.approx(6.0) and tg.size == 601
    assert np.max(np.abs(np.diff(x))) == pytest.approx(1.5 / 0.5 * ts, rel=1e-6)
    # without ramp: a pure staircase, mean of each hold equals its level
    s0 = StepSequence((2.0, -1.0), hold=1.0)
    tg, x = s0.sample(0.001)
    assert x[:1000].mean() == 2.0 and x[1000:2000].mean() == -1.0


@pytest.mark.parametrize("kw, pattern", [
    (dict(levels=(), hold=1.0), r"`levels`: empty"),
    (dict(levels=(0.0, float("nan")), hold=1.0), r"`levels\[1\]`: got nan, expected a finite number"),
    (dict(levels="01", hold=1.0), r"`levels`: got '01', expected a tuple of numbers"),
    (dict(levels=(1.0,), hold=0.0), r"`hold`: got 0\.0, expected a duration > 0 \(s\)"),
    (dict(levels=(1.0,), hold=1.0, ramp=1.0), r"`ramp`: got 1\.0, expected 0 <= ramp < hold = 1\.0 \(s\)"),
    (dict(levels=(1.0,), hold=1.0, ramp=-0.1), r"`ramp`: got -0\.1"),
])
def test_step_sequence_validation(kw, pattern):
    with pytest.raises(SpecError, match=r"StepSequence: " + pattern):
        StepSequence(**kw)


def test_step_sequence_is_frozen():
    s = StepSequence((1.0,), 1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.hold = 2.0


# ----------------------------------------------------------------------------- Chirp

@pytest.mark.parametrize("sweep, method", [("linear", "linear"), ("log", "logarithmic")])
def test_chirp_matches_scipy_chirp(sweep, method):
    c = Chirp(0.2, 8.0, duration=15.0, amplitude=1.7, sweep=sweep)
    t = np.linspace(0.0, 15.0, 30001)
    ref = 1.7 * sps.chirp(t, f0=0.2, t1=15.0, f1=8.0, method=method, phi=-90.0)   # cos(phase - 90 deg) = sin
    np.testing.assert_allclose(c.signal(t), ref, rtol=0, atol=1e-9)
    # instantaneous frequency: derivative of the phase
    f_num = np.gradient(c.phase(t), t) / (2 * np.pi)
    np.testing.assert_allclose(f_num[1:-1], c.frequency(t)[1:-1], rtol=1e-4)


@pytest.mark.parametrize("sweep", ["linear", "log"])
def test_chirp_zero_crossings_equal_twice_the_cycles(sweep):
    f0, f1, T = 0.5, 6.0, 12.0
    c = Chirp(f0, f1, T, 1.0, sweep=sweep)
    t = np.linspace(0.0, T, 200001)
    x = c.signal(t)
    crossings = np.count_nonzero(np.signbit(x[1:-1]) != np.signbit(x[2:]))
    cycles = (f0 + f1) / 2 * T if sweep == "linear" else (f1 - f0) * T / math.log(f1 / f0)   # integral of f(t)
    assert abs(crossings - 2 * cycles) <= 2


def test_chirp_fade_and_spectrum_inside_band():
    c = Chirp(1.0, 10.0, duration=20.0, amplitude=0.3, sweep="log", fade=2.0, ts=0.005)
    assert c.envelope(np.array([1.0]))[0] == pytest.approx(0.5, abs=1e-15)        # (1 - cos(pi/2)) / 2
    assert c.envelope(np.array([19.0]))[0] == pytest.approx(0.5, abs=1e-15)
    tq = np.array([0.5, 1.5, 18.5, 19.5])                 # quarter and three quarters of the fades
    q = 0.5 * (1 - math.cos(math.pi / 4))
    np.testing.assert_allclose(c.envelope(tq), [q, 1 - q, 1 - q, q], rtol=1e-12)
    np.testing.assert_array_equal(c.envelope(np.array([-0.1, 0.0, 10.0, 20.0, 20.1])), [0, 0, 1, 0, 0])
    t, x = c.sample()
    assert t.size == 4001 and x[0] == 0.0 and abs(x[-1]) < 1e-15
    assert np.max(np.abs(x)) == pytest.approx(0.3, rel=1e-3)
    assert np.max(np.abs(x[t < 0.5])) <= 0.3 * 0.5 * (1 - math.cos(math.pi * 0.25)) + 1e-12
    # with the fades, >= 97 % of the energy lies in the swept band (1-10 Hz, +-20 %)
    X = np.abs(np.fft.rfft(np.r_[x, np.zeros(x.size)])) ** 2
    f = np.fft.rfftfreq(2 * x.size, 0.005)
    inside = (f >= 0.8) & (f <= 12.0)
    assert X[inside].sum() / X.sum() >= 0.97


@pytest.mark.parametrize("kw, pattern", [
    (dict(f0=0.0, f1=5.0, duration=10.0, amplitude=1.0, sweep="log"),
     r"`f0`: got 0\.0, expected f0 > 0 \(Hz\) for a log sweep"),
    (dict(f0=-1.0, f1=5.0, duration=10.0, amplitude=1.0), r"`f0`: got -1\.0, expected a frequency >= 0"),
    (dict(f0=0.1, f1=30.0, duration=10.0, amplitude=1.0, ts=0.02),
     r"`f1`: got 30\.0 Hz, expected below the Nyquist frequency 1/\(2 ts\) = 25 Hz for ts = 0\.02 s"),
    (dict(f0=0.1, f1=5.0, duration=10.0, amplitude=1.0, fade=6.0),
     r"`fade`: got 6\.0, expected 0 <= fade <= duration/2 = 5\.0"),
    (dict(f0=0.1, f1=5.0, duration=10.0, amplitude=1.0, sweep="quadratic"),
     r"`sweep`: got 'quadratic', expected 'linear' or 'log'"),
    (dict(f0=0.1, f1=5.0, duration=0.0, amplitude=1.0), r"`duration`: got 0\.0, expected a duration > 0"),
    (dict(f0=0.1, f1=5.0, duration=10.0, amplitude=-1.0), r"`amplitude`: got -1\.0, expected a peak value > 0"),
    (dict(f0=2.0, f1=2.0, duration=10.0, amplitude=1.0), r"`f1`: got 2\.0 = f0"),
    (dict(f0=0.1, f1=float("inf"), duration=10.0, amplitude=1.0), r"`f1`: got inf, expected a finite number"),
])
def test_chirp_validation(kw, pattern):
    with pytest.raises(SpecError, match=r"Chirp: " + pattern):
        Chirp(**kw)


def test_chirp_sample_checks_nyquist_of_the_given_ts():
    c = Chirp(0.1, 20.0, 5.0, 1.0)
    t, x = c.sample(0.01)
    assert t.size == 501
    with pytest.raises(SpecError, match=r"`f1`: got 20\.0 Hz, expected below the Nyquist frequency"):
        c.sample(0.04)
    with pytest.raises(SpecError, match=r"Chirp\.sample: `ts`: not given"):
        c.sample()


def test_chirp_sample_refuses_a_grid_too_long_before_it_is_allocated():
    with pytest.raises(SpecError, match=r"Chirp\.sample: a duration of 5 s at a sample time of 1e-15 s is 5e\+15 "
                                        r"samples; expected at most 5,000,000"):
        Chirp(0.1, 20.0, 5.0, 1.0).sample(1e-15)  # 40 PB


# ----------------------------------------------------------------------------- band

def test_suggest_band_rule_and_nyquist_cap():
    lo, hi = suggest_band(2 * np.pi)                    # 1 Hz loop bandwidth
    assert (lo, hi) == pytest.approx((BAND_LOW_FACTOR, BAND_HIGH_FACTOR), rel=1e-15)
    assert (BAND_LOW_FACTOR, BAND_HIGH_FACTOR) == (0.1, 4.0)       # the documented rule
    lo, hi = suggest_band(2 * np.pi * 10.0, ts=0.02)   # 40 Hz would exceed Nyquist (25 Hz)
    assert lo == pytest.approx(1.0) and hi == pytest.approx(NYQUIST_FRACTION * 25.0)
    with pytest.raises(SpecError, match=r"`bandwidth_rad_s`: got -1\.0, expected a bandwidth > 0 \(rad/s\)"):
        suggest_band(-1.0)
    with pytest.raises(SpecError, match=r"too high for ts = 0\.1 s"):
        suggest_band(2 * np.pi * 100.0, ts=0.1)


@pytest.mark.parametrize("wc, ts", [(2.0, 0.02), (30.0, 0.01), (0.05, 0.1)])
def test_closed_loop_bandwidth_of_first_order_lag(wc, ts):
    a = math.exp(-wc * ts)
    g = ct.ss([[a]], [[1 - a]], [[1.0]], [[0.0]], ts)       # (1-a)/(z-a), DC gain 1
    # |G|^2 = (1-a)^2 / (1 - 2a cos(w ts) + a^2) = 1/2
    w_exact = math.acos((1 + a * a - 2 * (1 - a) ** 2) / (2 * a)) / ts
    assert closed_loop_bandwidth(g) == pytest.approx(w_exact, rel=1e-9)


def test_closed_loop_bandwidth_errors():
    with pytest.raises(SpecError, match=r"expected a discrete system with dt > 0"):
        closed_loop_bandwidth(ct.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]]))
    allpass = ct.ss([[0.0]], [[0.0]], [[0.0]], [[1.0]], 0.01)   # gain 1 everywhere
    with pytest.raises(SpecError, match=r"stays above -3 dB of its DC gain up to Nyquist"):
        closed_loop_bandwidth(allpass)


def _mag(sys: ct.StateSpace, w: np.ndarray) -> np.ndarray:
    A, B, C, D = (np.asarray(m, dtype=complex) for m in (sys.A, sys.B, sys.C, sys.D))
    eye = np.eye(A.shape[0])
    return np.array([abs((C @ np.linalg.solve(z * eye - A, B) + D)[0, 0]) for z in np.exp(1j * w * sys.dt)])


@pytest.mark.parametrize("i", [0, 1, 2])
def test_suggest_band_for_loop_uses_the_minus_3_db_point(fleet, i):
    lp = fleet.loops[i]
    lo, hi = suggest_band_for_loop(lp)
    wb = 2 * np.pi * lo / BAND_LOW_FACTOR
    g0 = _mag(lp.G_r, np.array([0.0]))[0]
    assert _mag(lp.G_r, np.array([wb]))[0] / g0 == pytest.approx(1 / math.sqrt(2), rel=1e-8)
    w_below = np.linspace(1e-4, wb * (1 - 1e-6), 400)
    assert np.all(_mag(lp.G_r, w_below) > g0 / math.sqrt(2))     # the first crossing, not a later one
    assert hi == pytest.approx(min(BAND_HIGH_FACTOR * wb / (2 * np.pi), NYQUIST_FRACTION * 0.5 / lp.ts), rel=1e-12)
    assert 0 < lo < hi < 0.5 / lp.ts


def test_suggest_band_for_loop_rejects_other_objects():
    with pytest.raises(SpecError, match=r"`loop`: got dict, expected an ilcdob\.LoopSystem"):
        suggest_band_for_loop({})


# ----------------------------------------------------------------------------- set-point CSV

def test_write_setpoint_csv_round_trip(tmp_path):
    c = Chirp(0.1, 4.0, 10.0, 0.5, fade=1.0, ts=0.02)
    t, a = c.sample()
    x = StepSequence((0.0, 1.0), 5.0, ramp=1.0).signal(t)
    path = tmp_path / "sp" / "setpoint.csv"
    fd = write_setpoint_csv(path, t, units={"x_ref": "m", "a_ref": "m/s^2"}, x_ref=x, a_ref=a)
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0] == "# units: time=s, x_ref=m, a_ref=m/s^2"
    assert lines[1] == "time,x_ref,a_ref"
    assert len(lines) == 2 + t.size and len(fd) == t.size
    back = load_csv(path, ["x_ref", "a_ref"])
    assert back.units == {"x_ref": "m", "a_ref": "m/s^2"} and back.metadata["resampled"] is False
    np.testing.assert_allclose(back.t, t, atol=1e-12)
    np.testing.assert_allclose(back["x_ref"], x, atol=1e-10)
    np.testing.assert_allclose(back["a_ref"], a, atol=1e-10)        # 10 significant digits


def test_write_setpoint_csv_errors(tmp_path):
    t = 0.01 * np.arange(10)
    with pytest.raises(SignalError, match=r"sp\.csv: no signals given"):
        write_setpoint_csv(tmp_path / "sp.csv", t)
    with pytest.raises(SignalError, match=r"sp\.csv: `units`: unknown signal\(s\) \['y'\]"):
        write_setpoint_csv(tmp_path / "sp.csv", t, units={"y": "m"}, x=t)
    with pytest.raises(SignalError, match=r"sp\.csv: signal `x`: expected 10 samples, got shape \(9,\)"):
        write_setpoint_csv(tmp_path / "sp.csv", t, x=t[:-1])
    with pytest.raises(SignalError, match=r"sp\.csv: signal `time`: not uniformly spaced"):
        write_setpoint_csv(tmp_path / "sp.csv", t ** 2 + t, x=t)
    assert not (tmp_path / "sp.csv").exists()
