"""FlightData helpers: cutting flights into windows (:func:`ilcdob.signals.segments`)."""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.errors import SpecError
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
