"""The paper's four validation scenarios (Sec. IV; docs/theory.md section 4), x axis only.

=====  =====================  ===========================================  ======  ============
id     trajectory             disturbance d(t) in x, m/s^2                 length  learning order
=====  =====================  ===========================================  ======  ============
1      hover at (0, 0, 2.5)   sin(0.9425 t)                                60 s    1 -> 2 -> 3
2      circle, R = 1 m        sin(0.9425 t)                                60 s    1 -> 2 -> 3
3      circle, R = 1 m        one half-sine gust, 2 sin(0.9425 (t - 20)),  40 s    1 -> 2 -> 3
                              20 s <= t <= 20 + pi/0.9425 s (3.33 s)
4      diamond, 2 m diagonal  max(0, sin(1.4138 t))                        60 s    1 -> 3 -> 2
=====  =====================  ===========================================  ======  ============

Trajectory speeds (chosen here; the paper does not print them):

* circle: 12 s period (0.52 m/s, centripetal acceleration 0.27 m/s^2), spun up smoothly over
  its first 6 s (cosine speed ramp) so the vehicle starts at rest on the circle at x = 0;
* diamond: vertices at x = 0, +1, 0, -1 m (y = -1, 0, 1, 0 m). The path has sharp corners
  and is flown as a waypoint mission flies it: each edge (sqrt(2) m) is a minimum-jerk
  move of 5 s that stops at the vertex (peak speed 0.53 m/s), 20 s per lap, after a 2 s
  hold. A constant-speed pass through a sharp corner would need an infinite acceleration.

Each scenario gives the reference position and its acceleration (analytic), which
controllers with ``acceleration_feedforward`` add to their output. Orders name fleet
positions: with a fleet of three systems scenario 4 flies the 1st, 3rd, 2nd; with any other
size it flies the file order. Every system also carries its own noise
(:class:`~ilcdob.specs.NoiseSpec`), added to the disturbance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ilcdob.errors import SpecError

__all__ = ["Scenario", "SCENARIOS", "scenario", "parse_scenarios"]

W_DIST = 0.9425        # rad/s, disturbance frequency of scenarios 1-3
W_DIAMOND = 1.4138     # rad/s, scenario 4
CIRCLE_RADIUS = 1.0    # m
CIRCLE_PERIOD = 12.0   # s
CIRCLE_SPINUP = 6.0    # s
GUST_START = 20.0      # s
GUST_AMPLITUDE = 2.0   # m/s^2
DIAMOND_HALF_DIAGONAL = 1.0  # m
DIAMOND_EDGE_TIME = 5.0  # s per edge (minimum-jerk, stop at every vertex)
DIAMOND_HOLD = 2.0     # s


@dataclass(frozen=True)
class Scenario:
    """One validation scenario.

    Attributes
    ----------
    id : int
    title : str
    duration : float, s
    reference : callable t -> x_ref (m)
    acceleration : callable t -> d^2 x_ref/dt^2 (m/s^2)
    disturbance : callable t -> d (m/s^2)
    order3 : tuple of int
        Learning order as 0-based fleet positions for a fleet of three systems.
    """

    id: int
    title: str
    duration: float
    reference: Callable[[np.ndarray], np.ndarray]
    acceleration: Callable[[np.ndarray], np.ndarray]
    disturbance: Callable[[np.ndarray], np.ndarray]
    order3: tuple[int, ...] = (0, 1, 2)

    def time(self, ts: float) -> np.ndarray:
        """Sample times ``k*ts`` over the scenario, s.

        Parameters
        ----------
        ts : float
            Sample time, s.
        """
        return np.arange(int(round(self.duration / ts))) * ts

    def order(self, names: list[str]) -> list[str]:
        """Learning order for a fleet with these system names.

        Parameters
        ----------
        names : list of str
            The fleet's system names, in fleet order; with three systems they are reordered
            by ``order3``, otherwise kept.
        """
        if len(names) == 3:
            return [names[i] for i in self.order3]
        return list(names)


def _zero(t: np.ndarray) -> np.ndarray:
    return np.zeros_like(t)


def _circle_phase(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phase, phase rate and phase acceleration of the spun-up circle."""
    w = 2 * np.pi / CIRCLE_PERIOD
    tr = CIRCLE_SPINUP
    tau = np.minimum(t, tr)
    on = t < tr
    # speed ramp w * (1 - cos(pi t / tr)) / 2 over the spin-up, then w
    phase = w * (0.5 * (tau - tr / np.pi * np.sin(np.pi * tau / tr)) + np.maximum(t - tr, 0.0))
    rate = np.where(on, 0.5 * w * (1 - np.cos(np.pi * tau / tr)), w)
    accel = np.where(on, 0.5 * w * np.pi / tr * np.sin(np.pi * tau / tr), 0.0)
    return phase, rate, accel


def _circle(t: np.ndarray) -> np.ndarray:
    phase, _, _ = _circle_phase(t)
    return CIRCLE_RADIUS * np.sin(phase)


def _circle_acc(t: np.ndarray) -> np.ndarray:
    phase, rate, accel = _circle_phase(t)
    return CIRCLE_RADIUS * (np.cos(phase) * accel - np.sin(phase) * rate**2)


_DIAMOND_X = np.array([0.0, 1.0, 0.0, -1.0])  # x of the vertices, times DIAMOND_HALF_DIAGONAL


def _diamond_edge(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start x, x-step and normalised time sigma in [0, 1] of the current edge."""
    tau = np.maximum(t - DIAMOND_HOLD, 0.0)
    edge = np.floor(tau / DIAMOND_EDGE_TIME).astype(int)
    sigma = tau / DIAMOND_EDGE_TIME - edge
    x0 = DIAMOND_HALF_DIAGONAL * _DIAMOND_X[edge % 4]
    x1 = DIAMOND_HALF_DIAGONAL * _DIAMOND_X[(edge + 1) % 4]
    return x0, x1 - x0, sigma


def _diamond(t: np.ndarray) -> np.ndarray:
    x0, dx, s = _diamond_edge(t)
    return x0 + dx * (10 * s**3 - 15 * s**4 + 6 * s**5)


def _diamond_acc(t: np.ndarray) -> np.ndarray:
    _, dx, s = _diamond_edge(t)
    return dx / DIAMOND_EDGE_TIME**2 * (60 * s - 180 * s**2 + 120 * s**3)


def _sine(t: np.ndarray) -> np.ndarray:
    return np.sin(W_DIST * t)


def _gust(t: np.ndarray) -> np.ndarray:
    tau = t - GUST_START
    on = (tau >= 0) & (tau <= np.pi / W_DIST)
    return np.where(on, GUST_AMPLITUDE * np.sin(W_DIST * tau), 0.0)


def _half_wave(t: np.ndarray) -> np.ndarray:
    return np.maximum(0.0, np.sin(W_DIAMOND * t))


SCENARIOS: dict[int, Scenario] = {
    1: Scenario(1, "Hover, sinusoidal wind", 60.0, _zero, _zero, _sine),
    2: Scenario(2, "Circle, sinusoidal wind", 60.0, _circle, _circle_acc, _sine),
    3: Scenario(3, "Circle, gust", 40.0, _circle, _circle_acc, _gust),
    4: Scenario(4, "Diamond, half-wave wind", 60.0, _diamond, _diamond_acc, _half_wave, (0, 2, 1)),
}


def scenario(sid: int) -> Scenario:
    """The scenario with id ``sid`` (1-4).

    Parameters
    ----------
    sid : int
        Scenario id, 1-4.

    Raises
    ------
    SpecError
        Unknown id.
    """
    if sid not in SCENARIOS:
        raise SpecError(f"`scenario`: got {sid!r}, valid ids are {sorted(SCENARIOS)}")
    return SCENARIOS[sid]


def parse_scenarios(text: str) -> list[int]:
    """Parse ``"1,2,4"`` into ``[1, 2, 4]`` (duplicates dropped, order kept).

    Parameters
    ----------
    text : str
        Comma-separated scenario ids.

    Raises
    ------
    SpecError
        An item that is not a valid id; the message names it and the valid ids.
    """
    ids = []
    for item in text.split(","):
        item = item.strip()
        if not item.isdigit() or int(item) not in SCENARIOS:
            raise SpecError(f"`--scenarios`: got {item!r} in {text!r}; valid ids are "
                            f"{sorted(SCENARIOS)}, comma-separated")
        if int(item) not in ids:
            ids.append(int(item))
    return ids
