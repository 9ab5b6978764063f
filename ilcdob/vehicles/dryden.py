"""Dryden turbulence: a wind velocity to fly vehicles in (docs/theory.md section 6).

The Dryden model (MIL-F-8785C; MIL-HDBK-1797) gives each component of the turbulent wind a
rational spectrum, so it is white noise through a shaping filter. With airspeed ``V`` (m/s; the
speed at which the frozen turbulence field is carried past the vehicle; for a hovering vehicle
the mean wind), length scale ``L`` (m) and intensity ``sigma`` (m/s), the one-sided spectra in
``w`` (rad/s) are::

    longitudinal  Phi_u(w) = sigma_u^2 (2 L_u / (pi V)) / (1 + (L_u w / V)^2)
    lateral       Phi_v(w) = sigma_v^2 (L_v / (pi V)) (1 + 3 (L_v w / V)^2) / (1 + (L_v w / V)^2)^2

(the vertical component as the lateral one with ``L_w``, ``sigma_w``). ``int_0^inf Phi dw =
sigma^2``. The longitudinal component is a first-order Gauss-Markov process with time constant
``L_u / V``, sampled exactly (an AR(1) recursion); the others are their shaping filters
``sigma sqrt(L/(pi V)) (1 + sqrt(3) L s / V) / (1 + L s / V)^2`` driven by white noise of
intensity ``pi`` (autocorrelation ``pi delta(t)``: then ``Phi = |H|^2``), i.e. variance ``pi/Ts``
per sample held over it, discretised with a zero-order hold, a close approximation below a tenth
of the sample rate.

Low-altitude defaults (below 1000 ft, MIL-F-8785C), ``h`` the altitude in ft and ``W20`` the
wind speed at 20 ft: ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``, ``sigma_w =
0.1 W20``, ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4``
(:meth:`DrydenWind.low_altitude` takes metres and m/s).
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sps

from ilcdob.errors import SpecError
from ilcdob.signals import check_grid

__all__ = ["DrydenWind"]

_FT = 0.3048  # m per ft


class DrydenWind:
    """A sampled Dryden wind, ``(3,)`` m/s in the world frame (x along the mean wind), as a callable of time.

    Parameters
    ----------
    duration : float
        Length of the series, s (> 0); beyond it the last sample holds.
    ts : float
        Sample time, s (> 0).
    mean : array_like
        Mean wind, ``(3,)`` m/s (added to the turbulence).
    sigma : array_like
        Intensities ``(sigma_u, sigma_v, sigma_w)``, m/s (>= 0).
    length : array_like
        Length scales ``(L_u, L_v, L_w)``, m (> 0).
    airspeed : float
        Speed carrying the turbulence past the vehicle, m/s (> 0; default: the mean wind's, at
        least 1 m/s).
    seed : int
        Seed of the white noise.
    """

    def __init__(self, duration: float, ts: float, *, mean: object = (0.0, 0.0, 0.0), sigma: object = (1.0, 1.0, 0.5),
                 length: object = (200.0, 200.0, 50.0), airspeed: float | None = None, seed: int = 0):
        if not (np.isfinite(duration) and duration > 0):
            raise SpecError(f"`duration`: got {duration!r}, expected a length > 0 s")
        if not (np.isfinite(ts) and 0 < ts < duration):
            raise SpecError(f"`ts`: got {ts!r}, expected a sample time in (0, duration) s")
        check_grid(duration, ts, "DrydenWind")
        self.mean = self._vector(mean, "mean", lambda v: np.all(np.isfinite(v)), "finite m/s")
        self.sigma = self._vector(sigma, "sigma", lambda v: np.all(v >= 0), "intensities >= 0 m/s")
        self.length = self._vector(length, "length", lambda v: np.all(v > 0), "length scales > 0 m")
        speed = max(1.0, float(np.linalg.norm(self.mean))) if airspeed is None else airspeed
        if not (np.isfinite(speed) and speed > 0):
            raise SpecError(f"`airspeed`: got {airspeed!r}, expected a speed > 0 m/s")
        self.ts, self.airspeed = float(ts), float(speed)
        n = int(np.ceil(duration / ts)) + 1
        white = np.random.default_rng(seed).standard_normal((n, 3))
        out = np.empty((n, 3))
        tau = self.length / self.airspeed  # s
        phi = np.exp(-ts / tau[0])  # longitudinal: the exact AR(1) of a first-order Gauss-Markov process
        out[:, 0] = sps.lfilter([self.sigma[0] * np.sqrt(1 - phi**2)], [1.0, -phi], white[:, 0])
        for i in (1, 2):
            gain = self.sigma[i] * np.sqrt(self.length[i] / (np.pi * self.airspeed))
            num, den = gain * np.array([np.sqrt(3.0) * tau[i], 1.0]), np.polymul([tau[i], 1.0], [tau[i], 1.0])
            b, a, _ = sps.cont2discrete((num, den), ts, method="zoh")
            # white noise of intensity pi, held over each sample: variance pi / ts
            out[:, i] = sps.lfilter(np.ravel(b), a, white[:, i] * np.sqrt(np.pi / ts))
        self.series = out + self.mean

    @staticmethod
    def _vector(value: object, name: str, ok, valid: str) -> np.ndarray:
        v = np.asarray(value, float).reshape(-1)
        if v.shape != (3,) or not ok(v):
            raise SpecError(f"`{name}`: got {value!r}, expected 3 {valid}")
        return v

    @classmethod
    def low_altitude(cls, duration: float, ts: float, altitude: float, wind_20ft: float, *,
                     direction: float = 0.0, seed: int = 0) -> "DrydenWind":
        """MIL-F-8785C low-altitude intensities and length scales (module docstring).

        Parameters
        ----------
        duration, ts : float
            As in :class:`DrydenWind`, s.
        altitude : float
            Height above ground, m (0.5 m to 300 m).
        wind_20ft : float
            Mean wind speed at 20 ft (6.1 m), m/s (>= 0); also the mean wind, along ``direction``.
        direction : float
            Direction of the mean wind from the x axis, rad (turbulence is along/across it).
        seed : int
            Seed of the white noise.

        Returns
        -------
        DrydenWind
            With x the along-wind axis rotated by ``direction`` (the series is in the world frame).
        """
        if not (np.isfinite(altitude) and 0.5 <= altitude <= 300.0):
            raise SpecError(f"`altitude`: got {altitude!r}, expected 0.5 m to 300 m (the low-altitude model)")
        if not (np.isfinite(wind_20ft) and wind_20ft >= 0):
            raise SpecError(f"`wind_20ft`: got {wind_20ft!r}, expected a wind speed >= 0 m/s")
        h = altitude / _FT
        f = 0.177 + 0.000823 * h
        l_w, l_uv = h * _FT, h / f**1.2 * _FT
        s_w = 0.1 * wind_20ft
        s_uv = s_w / f**0.4
        out = cls(duration, ts, mean=(wind_20ft, 0.0, 0.0), sigma=(s_uv, s_uv, s_w), length=(l_uv, l_uv, l_w),
                  seed=seed)
        c, s = np.cos(direction), np.sin(direction)
        out.series = out.series @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        return out

    def __call__(self, t: float) -> np.ndarray:
        """The wind at time ``t`` (s), ``(3,)`` m/s: the sample at or before it."""
        k = int(np.clip(np.floor(t / self.ts + 1e-9), 0, self.series.shape[0] - 1))
        return self.series[k].copy()
