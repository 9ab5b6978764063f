"""Benchmark: ilcdob's ``tfest`` against a plain output-error fit on the hard identification cases.

The plain fit shares no code with ilcdob: ``scipy.optimize.least_squares`` (trust-region
reflective, finite-difference Jacobian) over the free denominator and numerator coefficients
plus an output offset, each model simulated by ``scipy.signal.cont2discrete`` (zero-order hold)
and ``scipy.signal.lfilter`` from rest, the delay an integer number of samples searched over a
stated grid; started from several pole placements (all poles at one frequency, over a
logarithmic grid of frequencies in the data's band) and the best kept. Both fits run in the same
process on the same data; reported: held-out fit % of each (the held-out fit of the plain model
with its offset refitted on the held-out data), the true plant's, and the time ratio
plain / ilcdob.

Cases (built here, as in ``tests/test_tfest_hard.py``):

* flexible: a three-mass chain, 6 poles and 5 zeros, resonances at 1.3, 6.0 and 12.9 rad/s;
* thermal: ``1/((60 s + 1)(15 s + 1))`` with a 12 s delay, sampled every 2 s (delay estimated);
* unstable: ``2/((s - 0.5)(s + 3))`` flown in closed loop (``--allow-unstable``).

Run:  python benchmarks/bench_tfest_hard.py
"""

from __future__ import annotations

import time
import warnings

import control as ct
import numpy as np
from scipy import optimize
from scipy import signal as sps

from ilcdob.identification.tfest import FitOptions, tfest
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure


def _fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - np.mean(y))))


def _simulate(num: np.ndarray, den: np.ndarray, u: np.ndarray, ts: float, lag: int) -> np.ndarray:
    b, a, _ = sps.cont2discrete((num, den), ts, method="zoh")
    ud = np.concatenate([np.zeros(lag), u[: u.size - lag]]) if lag else u
    return sps.lfilter(np.ravel(b), a, ud)


def plain_oe(u: np.ndarray, y: np.ndarray, ts: float, n_poles: int, n_zeros: int, lags: list[int],
             stable: bool = True) -> tuple[np.ndarray, np.ndarray, int, float]:
    """The plain fit (module docstring): ``(num, den, lag, offset)`` of the best start and lag."""
    nyq = np.pi / ts
    best = (np.inf, None)
    for lag in lags:
        for w in np.geomspace(2e-3 * nyq, 0.3 * nyq, 6):
            den0 = np.real(np.poly(np.full(n_poles, -w)))
            x0 = np.concatenate([den0[1:], np.zeros(n_zeros), [den0[-1]], [0.0]])

            def resid(x, lag=lag):
                den = np.concatenate([[1.0], x[:n_poles]])
                if stable and np.any(np.roots(den).real >= 0):
                    return np.full(y.size, 1e3 * np.std(y))
                with np.errstate(all="ignore"):
                    r = _simulate(x[n_poles:-1], den, u, ts, lag) + x[-1] - y
                return r if np.all(np.isfinite(r)) else np.full(y.size, 1e3 * np.std(y))

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sol = optimize.least_squares(resid, x0, max_nfev=400 * x0.size)
            cost = float(np.sum(resid(sol.x) ** 2))
            if cost < best[0]:
                best = (cost, (sol.x, lag))
    x, lag = best[1]
    return x[n_poles:-1], np.concatenate([[1.0], x[:n_poles]]), lag, float(x[-1])


def _flexible():
    m = np.diag([1.0, 0.5, 0.8])
    k = np.array([[44.0, -40.0, 0.0], [-40.0, 65.0, -25.0], [0.0, -25.0, 25.0]])
    c = np.array([[0.85, -0.05, 0.0], [-0.05, 0.09, -0.04], [0.0, -0.04, 0.04]])
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(m, k), -np.linalg.solve(m, c)]])
    b = np.concatenate([np.zeros(3), np.linalg.solve(m, [1.0, 0.0, 0.0])])[:, None]
    tf = ct.tf(ct.ss(a, b, [[1.0, 0.5, 0.3, 0.2, 0.1, 0.05]], 0.0))
    num, den = np.real(tf.num[0][0]), np.real(tf.den[0][0])
    ts, data = 0.01, []
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        u = np.repeat(rng.standard_normal(301), 20)[:6000]
        y = _simulate(num, den, u, ts, 0)
        data.append((u, y + 0.02 * np.std(y) * rng.standard_normal(u.size)))
    return "flexible (6 poles, 5 zeros)", ts, num, den, 0, data, ModelStructure(6, 5, 0), FitOptions(), [0], True


def _thermal():
    num, den, ts, data = np.array([1.0]), np.polymul([60.0, 1.0], [15.0, 1.0]), 2.0, []
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        u = np.repeat(rng.choice([-1.0, 1.0], 61), 60)[:3600]
        data.append((u, _simulate(num, den, u, ts, 6) + 0.01 * rng.standard_normal(u.size)))
    return ("thermal (2 poles, 12 s delay, Ts 2 s)", ts, num, den, 6, data, ModelStructure(2, 0, 0),
            FitOptions(delay="auto"), list(range(0, 16)), True)


def _unstable():
    p = ct.tf([2.0], np.polymul([1.0, -0.5], [1.0, 3.0]))
    ts, n, data = 0.01, 3000, []
    t = np.arange(n) * ts
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        r = np.repeat(rng.choice([-1.0, 1.0], n // 200 + 1), 200)[:n]
        v = 0.5 * np.repeat(rng.standard_normal(n // 10 + 1), 10)[:n]
        u = ct.forced_response(ct.c2d(ct.feedback(1, 2 * p), ts, "zoh"), T=t, U=2 * r + v).outputs
        y = ct.forced_response(ct.c2d(p, ts, "zoh"), T=t, U=u).outputs
        data.append((u, y + 0.002 * rng.standard_normal(n)))
    num, den = np.real(p.num[0][0]), np.real(p.den[0][0])
    return ("unstable, closed loop (2 poles)", ts, num, den, 0, data, ModelStructure(2, 0, 0),
            FitOptions(stable=False), [0], False)


def main() -> None:
    print(f"{'case':<40} {'truth':>7} {'ilcdob':>7} {'plain':>7} {'t ilcdob':>9} {'t plain':>8} {'ratio':>6}")
    for case in (_flexible, _thermal, _unstable):
        name, ts, num, den, lag, data, structure, opts, lags, stable = case()
        (ue, ye), (uv, yv) = data
        flights = [FlightData(np.arange(u.size) * ts, {"u": u, "y": y}) for u, y in data]
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = tfest(flights[0], "u", "y", structure, opts, validation=flights[1], progress=None)
        t_ilc = time.perf_counter() - t0
        t0 = time.perf_counter()
        pn, pd, plag, _ = plain_oe(ue, ye, ts, structure.n_poles, structure.n_zeros, lags, stable)
        t_plain = time.perf_counter() - t0
        yhat = _simulate(pn, pd, uv, ts, plag)
        plain_fit = _fit_percent(yv, yhat + np.mean(yv - yhat))
        truth = _simulate(num, den, uv, ts, lag)
        truth_fit = _fit_percent(yv, truth + np.mean(yv - truth))
        print(f"{name:<40} {truth_fit:7.2f} {est.fit_validation:7.2f} {plain_fit:7.2f} {t_ilc:8.2f}s "
              f"{t_plain:7.2f}s {t_plain / t_ilc:6.1f}")


if __name__ == "__main__":
    main()
