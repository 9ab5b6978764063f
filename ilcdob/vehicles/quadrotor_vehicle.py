"""The in-house 6-DOF quadrotor (:mod:`ilcdob.vehicles.quadrotor`) as a :class:`~ilcdob.vehicles.interface.Vehicle`.

:func:`~ilcdob.vehicles.interface.fly_vehicle` flies it as it flies rotorpy's multirotors
(:mod:`ilcdob.vehicles.rotorpy_vehicle`): an acceleration command per axis goes in at the outer
rate ``ts``, a measured position comes out. Inside, the vehicle keeps its own integration: each
:meth:`QuadrotorVehicle.step` limits the command's tilt and thrust (:func:`~ilcdob.vehicles.quadrotor.limit_tilt`,
as its flight stack does) and runs ``ts * inner_rate_hz`` inner steps of the rigid body, its inner
loops and RK4 (:func:`~ilcdob.vehicles.quadrotor.make_advance`), the command held over them.

The disturbance is an external x acceleration on the airframe (force / mass, m/s^2: wind and the
vehicle's noise), a vectorised callable of time evaluated on the inner grid. With ``horizon``
(samples) it is evaluated once, over ``horizon`` outer samples, when the vehicle is made; without,
one outer step at a time.

What a flight log would not show is kept for the simulation's own records: :attr:`QuadrotorVehicle.truth`
(the true position at every :meth:`~QuadrotorVehicle.position`) and :attr:`QuadrotorVehicle.saturated`
(steps whose horizontal command the tilt limit scaled down), both since the last reset.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.signals import as_signal
from ilcdob.specs import check_noise_std

from .quadrotor import QuadrotorParams, limit_tilt, make_advance

__all__ = ["QuadrotorVehicle"]


class QuadrotorVehicle:
    """One in-house quadrotor flown through ilcdob's vehicle protocol (module docstring).

    Parameters
    ----------
    params : QuadrotorParams
        The vehicle; its inner rate must be a multiple of ``1/ts``.
    ts : float
        Outer-loop sample time, s: each :meth:`step` integrates this long.
    disturbance : callable, optional
        External x acceleration on the airframe, m/s^2, a vectorised callable of time (s)
        (default: none).
    noise_std : float
        Standard deviation of the white position-sensor noise on x, y and z, m (>= 0).
    seed : int, numpy.random.SeedSequence or numpy.random.Generator
        Seed of the sensor noise, restarted at every :meth:`reset` (a ``Generator`` is drawn from
        as it stands: one trial's noise).
    horizon : int, optional
        Outer samples over which ``disturbance`` is evaluated at once (a trial's length); stepping
        past it evaluates the next outer steps one at a time.
    """

    def __init__(self, params: QuadrotorParams, ts: float, *, disturbance: Callable | None = None,
                 noise_std: float = 0.0, seed: int | np.random.SeedSequence | np.random.Generator = 0,
                 horizon: int | None = None):
        if not isinstance(params, QuadrotorParams):
            raise SpecError(f"`params`: got {type(params).__name__}, expected a QuadrotorParams")
        ratio = ts * params.inner_rate_hz
        nin = int(round(ratio))
        if nin < 1 or abs(ratio - nin) > 1e-9 * max(1.0, ratio):
            raise SpecError(f"`inner_rate_hz` of vehicle {params.name!r}: got {params.inner_rate_hz:g} Hz, expected "
                            f"a multiple of the outer rate 1/Ts = {1 / ts:g} Hz")
        if disturbance is not None and not callable(disturbance):
            raise SpecError(f"`disturbance`: got {type(disturbance).__name__}, expected a vectorised callable "
                            "of time (s) returning m/s^2")
        self.params, self.ts, self.nin = params, ts, nin
        self.noise_std = check_noise_std(noise_std, "noise_std")
        self.seed = seed
        self.disturbance = disturbance
        self._advance = make_advance(params)
        self._tan_max = math.tan(params.max_tilt)
        self._d: list[float] = []
        if horizon is not None:
            self._extend(int(horizon))
        self.reset()

    def _extend(self, samples: int) -> None:
        """The disturbance on the inner grid up to outer sample ``samples``."""
        j0, j1 = len(self._d), samples * self.nin
        if j1 <= j0:
            return
        t = np.arange(j0, j1) * self.params.inner_dt
        if self.disturbance is None:
            self._d.extend([0.0] * t.size)
            return
        d = as_signal(np.broadcast_to(np.asarray(self.disturbance(t), float), t.shape), "disturbance")
        self._d.extend(d.tolist())

    def reset(self) -> None:
        """Hover at rest at the origin, every inner state zero, the sensor noise restarted from ``seed``."""
        self._s = [0.0] * 6 + [1.0, 0.0, 0.0, 0.0] + [0.0] * 3 + [self.params.hover_rotor_speed] * 4
        self._wprev = (0.0, 0.0)
        self._k = 0
        self._rng = np.random.default_rng(self.seed)
        self.truth: list[tuple[float, float, float]] = []
        self.saturated = 0

    def position(self) -> np.ndarray:
        """Measured position, ``(3,)``, m: the true one (appended to :attr:`truth`) plus the sensor noise."""
        s = self._s
        self.truth.append((s[0], s[1], s[2]))
        if self.noise_std > 0:
            n = self._rng.normal(0.0, self.noise_std, size=3)
            return np.array([s[0] + n[0], s[1] + n[1], s[2] + n[2]])
        return np.array([s[0], s[1], s[2]])

    def step(self, command: np.ndarray) -> np.ndarray:
        """Hold an acceleration command for ``ts`` (module docstring).

        Parameters
        ----------
        command : array_like
            ``(3,)``, m/s^2, world frame, gravity excluded.

        Returns
        -------
        numpy.ndarray
            The command applied: ``z`` within ``[-G/2, G]``, the horizontal part scaled to the tilt limit.
        """
        a = np.asarray(command, float).reshape(-1).tolist()  # scalar code from here: the hot loop is per sample
        if len(a) != 3 or not (math.isfinite(a[0]) and math.isfinite(a[1]) and math.isfinite(a[2])):
            raise SpecError(f"`command`: got {command!r}, expected 3 finite accelerations (m/s^2)")
        ax, ay, az, limited = limit_tilt(a[0], a[1], a[2], self._tan_max)
        self.saturated += limited
        self._extend(self._k + 1)
        self._s, self._wprev = self._advance(self._s, ax, ay, az, self._d, self._k * self.nin, self.nin,
                                             self._wprev, None)
        self._k += 1
        return np.array([ax, ay, az])
