"""FlightData helpers: cutting flights into windows (:func:`ilcdob.signals.segments`), the gaps of resampled
time stamps, and the bound on a time grid's length."""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.errors import SignalError, SpecError
from ilcdob.signals import MIN_WINDOW_SAMPLES, FlightData, segments


def _flight(n: int, ts: float = 0.02, t0: float = 3.7) -> FlightData:
    return FlightData(t0 + np.arange(n) * ts, {"x": np.arange(n, dtype=float)}, source="f.csv")


@pytest.mark.parametrize("n, lengths", [
    (1500, [500, 500, 500]),          # whole windows
    (1750, [500, 500, 750]),          # a tail of exactly half a window joins the last window
    (1751, [500, 500, 500, 251]),     # a tail of more than half a window is a window of its own
    (1999, [500, 500, 500, 499]),
    (400, [400]),                     # shorter than one window: the flight whole
    (700, [700]),                     # one window and less than half another: whole
])
def test_windows_of_10_s_at_50_hz(n, lengths):
    fd = _flight(n)
    parts = segments([fd], 10.0)
    assert [len(p) for p in parts] == lengths
    assert np.array_equal(np.concatenate([p["x"] for p in parts]), fd["x"])  # each sample once, in order
    for p in parts:  # each window records its first and last time stamp
        assert p.metadata["segment"] == [p.t[0], p.t[-1]]
        assert p.source == fd.source


def test_window_length_is_rounded_to_whole_samples():
    # 1.003 s at 0.01 s: round(100.3) = 100 samples per window, no sample lost between windows
    fd = _flight(1000, ts=0.01)
    parts = segments([fd], 1.003)
    assert [len(p) for p in parts] == [100] * 10
    assert np.array_equal(np.concatenate([p["x"] for p in parts]), fd["x"])


def test_each_flight_is_cut_on_its_own():
    a, b = _flight(1200), _flight(600, t0=100.0)
    parts = segments([a, b], 5.0)
    assert [len(p) for p in parts] == [250, 250, 250, 250, 200, 250, 350]
    assert parts[4].t[0] == pytest.approx(a.t[1000]) and parts[5].t[0] == pytest.approx(100.0)


def test_a_tail_below_min_samples_is_merged():
    # n = 40, tail 30 > 20 but below min_samples 35: merged into the last window
    assert [len(p) for p in segments([_flight(110)], 0.8, min_samples=35)] == [40, 70]
    assert [len(p) for p in segments([_flight(110)], 0.8, min_samples=30)] == [40, 40, 30]


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf"), "10", True, None])
def test_bad_lengths_name_the_input(value):
    with pytest.raises(SpecError, match=r"`--segment`: got .*finite number > 0"):
        segments([_flight(100)], value, name="--segment")


def test_windows_too_short_name_the_samples_and_the_minimum():
    with pytest.raises(SpecError) as info:
        segments([_flight(100)], 0.1, name="--segment")
    msg = str(info.value)
    # 0.1 s at 0.02 s is 5 samples, below MIN_WINDOW_SAMPLES = 10 (0.2 s)
    assert MIN_WINDOW_SAMPLES == 10
    assert "`--segment`" in msg and "5 samples" in msg and "f.csv" in msg and "at least 0.2 s" in msg


def test_resampling_records_every_missing_sample_apart_from_the_gaps_identification_cuts_at():
    one = np.delete(np.arange(500) * 0.02, 300)  # a step of 2 median steps: below GAP_FACTOR, one sample missing
    fd = FlightData.from_samples({"x": (one, np.sin(one))})
    assert "gaps" not in fd.metadata and len(fd.pieces()) == 1  # identification as before: one piece
    assert fd.metadata["sample_gaps"] == [[pytest.approx(5.98), pytest.approx(6.02)]]
    assert fd.missing_samples() == [(pytest.approx(5.98), pytest.approx(6.02), 1)]
    many = np.delete(np.arange(500) * 0.02, list(range(200, 250)) + [400])  # t = 4.0 to 4.98 s, and 8.0 s
    fd = FlightData.from_samples({"x": (many, np.cos(many)), "y": (many, many)})
    assert len(fd) == 500 and fd.metadata["gaps"] == [[pytest.approx(3.98), pytest.approx(5.0)]]
    assert [g[2] for g in fd.missing_samples()] == [50, 1]
    # a segment before, between or after the gaps has none; one across a gap keeps it
    assert fd.segment(None, 3.98).missing_samples() == [] and fd.segment(5.0, 7.98).missing_samples() == []
    assert fd.segment(8.02, None).missing_samples() == []
    assert [g[2] for g in fd.segment(4.5, 7.0).missing_samples()] == [50]


def test_a_jittered_but_complete_log_misses_no_sample_and_a_missing_row_is_still_seen():
    rng = np.random.default_rng(7)
    t = np.arange(500) * 0.02 + rng.uniform(-0.03, 0.03, 500) * 0.02  # every stamp off by up to 3 % of a step
    assert FlightData.from_samples({"x": (t, np.sin(t))}).missing_samples() == []
    t = np.delete(t, 300)
    assert [g[2] for g in FlightData.from_samples({"x": (t, np.sin(t))}).missing_samples()] == [1]


def test_a_grid_too_long_for_memory_is_refused_before_it_is_allocated():
    # a median step of 1e-12 s over 100 s: 1e14 samples (800 TB); the message names the step, the span and the bound
    t = np.concatenate([np.arange(99) * 1e-12, [100.0]])
    with pytest.raises(SignalError) as info:
        FlightData.from_samples({"x": (t, np.ones(t.size))}, source="f.csv")
    msg = str(info.value)
    assert "f.csv" in msg and "1e-12 s" in msg and "0 to 100 s" in msg and "1e+14 samples" in msg
    assert "5,000,000" in msg


def test_check_grid_names_the_sample_time_the_duration_the_samples_and_the_bound():
    from ilcdob.signals import MAX_GRID_SAMPLES, check_grid

    check_grid(60.0, 0.001, "scenario 1")  # 60,000 samples
    check_grid(MAX_GRID_SAMPLES * 0.001, 0.001, "the longest")
    with pytest.raises(SpecError) as info:  # 1e-7 s over 1e9 s: 1e16 samples, 80 PB
        check_grid(1e9, 1e-7, "scenario 1")
    msg = str(info.value)
    assert "scenario 1" in msg and "1e-07 s" in msg and "1e+09 s" in msg and "1e+16 samples" in msg
    assert "5,000,000" in msg
