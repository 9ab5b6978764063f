"""The paper's four validation scenarios (Sec. IV; docs/theory.md section 4), flown in x.

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
  centre (0, 1 m), so it starts at (0, 0), at the hover point, and flies anticlockwise seen
  from above (x = R sin(phase), y = R (1 - cos(phase)));
* diamond: vertices at x = 0, +1, 0, -1 m (y = -1, 0, 1, 0 m). The path has sharp corners
  and is flown as a waypoint mission flies it: each edge (sqrt(2) m) is a minimum-jerk
  move of 5 s that stops at the vertex (peak speed 0.53 m/s), 20 s per lap, after a 2 s
  hold at the first vertex (0, -1 m); x and y share the timing. A constant-speed pass
  through a sharp corner would need an infinite acceleration.

Each scenario gives the reference position and its acceleration (analytic), which
controllers with ``acceleration_feedforward`` add to their output: in x, the axis the loops
fly (``reference``, ``acceleration``), and in 3-D (:meth:`Scenario.trajectory`: the same x,
y of the paths above, z = 2.5 m throughout). Orders name fleet positions: with a fleet of
three systems scenario 4 flies the 1st, 3rd, 2nd; with any other size it flies the file
order. An order given by name (:func:`check_order`, ``reproduce --order``) replaces them in
every scenario. Every system also carries its own noise
(:class:`~ilcdob.specs.NoiseSpec`), added to the disturbance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.signals import check_grid

__all__ = ["Scenario", "SCENARIOS", "scenario", "parse_scenarios", "check_order", "ALTITUDE"]

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
ALTITUDE = 2.5         # m, z of every trajectory


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
    lateral : callable t -> (y_ref, d^2 y_ref/dt^2), or None
        The path's y (m) and its acceleration (m/s^2) for :meth:`trajectory`; None: y = 0.
    """

    id: int
    title: str
    duration: float
    reference: Callable[[np.ndarray], np.ndarray]
    acceleration: Callable[[np.ndarray], np.ndarray]
    disturbance: Callable[[np.ndarray], np.ndarray]
    order3: tuple[int, ...] = (0, 1, 2)
    lateral: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None

    def time(self, ts: float) -> np.ndarray:
        """Sample times ``k*ts`` over the scenario, s.

        Parameters
        ----------
        ts : float
            Sample time, s.

        Raises
        ------
        SpecError
            More than :data:`ilcdob.signals.MAX_GRID_SAMPLES` samples (checked before the grid is
            allocated).
        """
        check_grid(self.duration, ts, f"scenario {self.id} ({self.title})")
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

    def trajectory(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Reference position and acceleration in 3-D (analytic; module docstring).

        Column x is :attr:`reference` and :attr:`acceleration` themselves, y comes from
        :attr:`lateral` (0 without it), z is :data:`ALTITUDE` (acceleration 0).

        Parameters
        ----------
        t : array_like
            Times, s (1-D).

        Returns
        -------
        position : numpy.ndarray
            ``(N, 3)`` reference positions ``(x, y, z)``, m.
        acceleration : numpy.ndarray
            ``(N, 3)`` their second time derivatives, m/s^2.
        """
        t = np.asarray(t, dtype=float)
        if self.lateral is None:
            y, ay = np.zeros_like(t), np.zeros_like(t)
        else:
            y, ay = self.lateral(t)
        position = np.column_stack([self.reference(t), y, np.full_like(t, ALTITUDE)])
        acceleration = np.column_stack([self.acceleration(t), ay, np.zeros_like(t)])
        return position, acceleration


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


def _circle_y(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """y = R (1 - cos(phase)) of the circle centred at (0, R), and its acceleration."""
    phase, rate, accel = _circle_phase(t)
    return (CIRCLE_RADIUS * (1 - np.cos(phase)),
            CIRCLE_RADIUS * (np.sin(phase) * accel + np.cos(phase) * rate**2))


_DIAMOND_X = np.array([0.0, 1.0, 0.0, -1.0])  # x of the vertices, times DIAMOND_HALF_DIAGONAL
_DIAMOND_Y = np.array([-1.0, 0.0, 1.0, 0.0])  # y of the vertices, times DIAMOND_HALF_DIAGONAL


def _diamond_edge(t: np.ndarray, vertices: np.ndarray = _DIAMOND_X) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start coordinate, step and normalised time sigma in [0, 1] of the current edge
    (``vertices``: that coordinate of the four vertices)."""
    tau = np.maximum(t - DIAMOND_HOLD, 0.0)
    edge = np.floor(tau / DIAMOND_EDGE_TIME).astype(int)
    sigma = tau / DIAMOND_EDGE_TIME - edge
    x0 = DIAMOND_HALF_DIAGONAL * vertices[edge % 4]
    x1 = DIAMOND_HALF_DIAGONAL * vertices[(edge + 1) % 4]
    return x0, x1 - x0, sigma


def _diamond(t: np.ndarray) -> np.ndarray:
    x0, dx, s = _diamond_edge(t)
    return x0 + dx * (10 * s**3 - 15 * s**4 + 6 * s**5)


def _diamond_acc(t: np.ndarray) -> np.ndarray:
    _, dx, s = _diamond_edge(t)
    return dx / DIAMOND_EDGE_TIME**2 * (60 * s - 180 * s**2 + 120 * s**3)


def _diamond_y(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """y of the diamond (the same minimum-jerk timing as x) and its acceleration."""
    y0, dy, s = _diamond_edge(t, _DIAMOND_Y)
    return (y0 + dy * (10 * s**3 - 15 * s**4 + 6 * s**5),
            dy / DIAMOND_EDGE_TIME**2 * (60 * s - 180 * s**2 + 120 * s**3))


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
    2: Scenario(2, "Circle, sinusoidal wind", 60.0, _circle, _circle_acc, _sine, lateral=_circle_y),
    3: Scenario(3, "Circle, gust", 40.0, _circle, _circle_acc, _gust, lateral=_circle_y),
    4: Scenario(4, "Diamond, half-wave wind", 60.0, _diamond, _diamond_acc, _half_wave, (0, 2, 1),
                lateral=_diamond_y),
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


def check_order(names: list[str], order: object, what: str = "order") -> list[str]:
    """A learning order given by system name, checked against the fleet's systems.

    Parameters
    ----------
    names : list of str
        The fleet's system names.
    order : sequence of str
        The systems in learning order: each a fleet system, each once, at least two (the
        single system of a one-system fleet may stand alone). Systems left out are not flown.
    what : str
        What the order is called where it was given (e.g. ``"--order"``), for messages.

    Returns
    -------
    list of str
        ``order`` as a list.

    Raises
    ------
    SpecError
        Not a sequence of names, too few names, an unknown or a repeated name; the message
        names them and the fleet's systems.
    """
    if isinstance(order, (str, bytes)) or not hasattr(order, "__iter__"):
        raise SpecError(f"`{what}`: got {order!r}, expected a list of system names (the fleet has {list(names)})")
    order = list(order)
    bad = [n for n in order if not isinstance(n, str)]
    if bad:
        raise SpecError(f"`{what}`: got {bad[0]!r} in {order!r}, expected system names (the fleet has {list(names)})")
    unknown = [n for n in order if n not in names]
    if unknown:
        raise SpecError(f"`{what}`: unknown system(s) {', '.join(map(repr, unknown))} in {order!r}; the fleet has "
                        f"{list(names)}")
    repeated = sorted({n for n in order if order.count(n) > 1}, key=order.index)
    if repeated:
        raise SpecError(f"`{what}`: {', '.join(map(repr, repeated))} given more than once in {order!r}; name each "
                        "system once (learning passes around the order and closes the cycle itself)")
    if len(order) < min(2, len(names)):
        raise SpecError(f"`{what}`: got {order!r}, expected at least two system names (a learning pair) of "
                        f"{list(names)}")
    return order


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
