"""Benchmark: ilcdob's ``tfest`` against a plain output-error fit on the hard identification cases.

The plain fit shares no code with ilcdob: ``scipy.optimize.least_squares`` (trust-region
reflective, finite-difference Jacobian) over the free denominator and numerator coefficients
plus an output offset per file, each model simulated by ``scipy.signal.cont2discrete`` (zero-order
hold) and ``scipy.signal.lfilter`` from rest, the delay an integer number of samples searched over
a stated grid. It runs from two sets of starts, each timed: "plain" from pole placements of its own
(all poles at one frequency, over a logarithmic grid of frequencies in the data's band), and "plain,
same starts" from ilcdob's own initial estimates (SRIVC, pole grid, frequency-domain fit, taken
from ilcdob before its search; the same number ilcdob runs from, ``FitOptions.starts``). Both fits
run in the same process on the same data; reported: held-out fit % of each (the plain model's offset
refitted on the held-out data), the true plant's where known, and the time ratios plain / ilcdob.
A ratio is only meaningful where the plain fit reaches ilcdob's fit: where it stops far below
(its trust region collapsing on the ill-conditioned polynomial coefficients of a lightly damped
6th-order model), the line says so.

Cases (built here, as in ``tests/test_tfest_hard.py``):

* flexible: a three-mass chain, 6 poles and 5 zeros, resonances at 1.3, 6.0 and 12.9 rad/s;
* thermal: ``1/((60 s + 1)(15 s + 1))`` with a 12 s delay, sampled every 2 s (delay estimated);
* unstable: ``2/((s - 0.5)(s + 3))`` flown in closed loop (``--allow-unstable``);
* lagging input: ``(2 s + 3)/(s^2 + 1.4 s + 4)`` with its input logged 5 samples late (delay
  estimated over [0, 0.15] s; the truth column is the causal plant on data misaligned alike);
* corrupt file: the same plant, four files, one with its output jumping 16 units over its last
  second (the truth column on a clean held-out file).

Run:  python benchmarks/bench_tfest_hard.py
"""

from __future__ import annotations

import importlib
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


def plain_oe(files: list[tuple[np.ndarray, np.ndarray]], ts: float, n_poles: int, n_zeros: int, lags: list[int],
             stable: bool = True, starts: list[np.ndarray] | None = None
             ) -> tuple[np.ndarray, np.ndarray, int]:
    """The plain fit (module docstring): ``(num, den, lag)`` of the best start and lag. ``starts``:
    ``(den, num)`` pairs to start from instead of the pole grid."""
    nyq = np.pi / ts
    if starts is None:
        starts = []
        for w in np.geomspace(2e-3 * nyq, 0.3 * nyq, 6):
            den0 = np.real(np.poly(np.full(n_poles, -w)))
            starts.append((den0, np.concatenate([np.zeros(n_zeros), [den0[-1]]])))
    scale = 1e3 * np.std(np.concatenate([y for _, y in files]))
    best = (np.inf, None)
    for lag in lags:
        for den0, num0 in starts:
            x0 = np.concatenate([den0[1:], num0, np.zeros(len(files))])

            def resid(x, lag=lag):
                den = np.concatenate([[1.0], x[:n_poles]])
                if stable and np.any(np.roots(den).real >= 0):
                    return np.full(sum(y.size for _, y in files), scale)
                with np.errstate(all="ignore"):
                    r = np.concatenate([_simulate(x[n_poles:n_poles + n_zeros + 1], den, u, ts, lag) + c - y
                                        for (u, y), c in zip(files, x[n_poles + n_zeros + 1:])])
                return r if np.all(np.isfinite(r)) else np.full(r.size, scale)

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    sol = optimize.least_squares(resid, x0, max_nfev=400 * x0.size)
                except (ValueError, np.linalg.LinAlgError):   # scipy's conversion of a diverged model
                    continue
            cost = float(np.sum(resid(sol.x) ** 2))
            if cost < best[0]:
                best = (cost, (sol.x, lag))
    x, lag = best[1]
    return x[n_poles:n_poles + n_zeros + 1], np.concatenate([[1.0], x[:n_poles]]), lag


def ilcdob_starts(flights: list[FlightData], structure: ModelStructure, opts: FitOptions) -> list:
    """ilcdob's initial estimates ``(den, num)`` at delay 0, as its search takes them (private API: the
    starts only, the optimiser is the plain fit's)."""
    tf = importlib.import_module("ilcdob.identification.tfest")
    exps, ts = tf._experiments(flights, "u", "y", structure, opts, tf._silent)
    model = tf._Model(structure, exps, ts, opts, False)
    return [structure.split(p.theta) for p in tf._candidates(model, 0.0, tf._silent)[: opts.starts]]


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
    return "flexible (6 poles, 5 zeros)", ts, num, den, 0, data[:1], data[1:], ModelStructure(6, 5, 0), FitOptions(), \
        [0], True


def _thermal():
    num, den, ts, data = np.array([1.0]), np.polymul([60.0, 1.0], [15.0, 1.0]), 2.0, []
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        u = np.repeat(rng.choice([-1.0, 1.0], 61), 60)[:3600]
        data.append((u, _simulate(num, den, u, ts, 6) + 0.01 * rng.standard_normal(u.size)))
    return ("thermal (2 poles, 12 s delay, Ts 2 s)", ts, num, den, 6, data[:1], data[1:], ModelStructure(2, 0, 0),
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
    return ("unstable, closed loop (2 poles)", ts, num, den, 0, data[:1], data[1:], ModelStructure(2, 0, 0),
            FitOptions(stable=False), [0], False)


def _stable_files(seeds, rng, ts: float = 0.01, n: int = 3000):
    """``(2 s + 3)/(s^2 + 1.4 s + 4)`` driven by a chirp plus random steps, 2 % noise."""
    num, den, out = np.array([2.0, 3.0]), np.array([1.0, 1.4, 4.0]), []
    t = np.arange(n) * ts
    for seed in seeds:
        steps = np.repeat(np.random.default_rng(seed).choice([-1.0, 1.0], n // 150 + 1), 150)[:n]
        u = 0.7 * np.sin(2 * np.pi * (0.05 * t + 3.0 * t**2 / (2 * t[-1]))) + 0.5 * steps
        out.append((u, _simulate(num, den, u, ts, 0) + 0.02 * rng.standard_normal(n)))
    return num, den, out


def _lagging():
    num, den, data = _stable_files((3, 4), np.random.default_rng(3))
    late = [(u[:-5], y[5:]) for u, y in data]               # the input logged 5 samples late
    return ("lagging input (5 samples late)", 0.01, num, den, 0, late[:1], late[1:], ModelStructure(2, 1, 0),
            FitOptions(delay="auto", max_delay=0.15), list(range(0, 16)), True)


def _corrupt():
    rng = np.random.default_rng(21)
    num, den, files = _stable_files(range(4), rng)
    files[2] = (files[2][0], files[2][1] + np.where(np.arange(3000) >= 2900, 16.0, 0.0))
    return ("corrupt file among four", 0.01, num, den, 0, files, _stable_files((7,), rng)[2],
            ModelStructure(2, 1, 0), FitOptions(), [0], True)


def _held_out(num, den, lag, val, ts) -> float:
    yhat = [_simulate(num, den, u, ts, lag) for u, _ in val]
    y = np.concatenate([y for _, y in val])
    return _fit_percent(y, np.concatenate([yh + np.mean(yv - yh) for yh, (_, yv) in zip(yhat, val)]))


def main() -> None:
    print(f"{'case':<34} {'truth':>6} {'ilcdob':>7} {'plain':>6} {'same':>6} {'t ilcdob':>9} {'t plain':>8} "
          f"{'t same':>7} {'ratio':>6} {'same':>5}")
    for case in (_flexible, _thermal, _unstable, _lagging, _corrupt):
        name, ts, num, den, lag, est_data, val_data, structure, opts, lags, stable = case()
        flights = [FlightData(np.arange(u.size) * ts, {"u": u, "y": y}, source=f"file {i + 1}")
                   for i, (u, y) in enumerate(est_data)]
        validation = [FlightData(np.arange(u.size) * ts, {"u": u, "y": y}) for u, y in val_data]
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = tfest(flights, "u", "y", structure, opts, validation=validation, progress=None)
        t_ilc = time.perf_counter() - t0
        fits, times = [], []
        for starts in (None, ilcdob_starts(flights, structure, opts)):
            t0 = time.perf_counter()
            pn, pd, plag = plain_oe(est_data, ts, structure.n_poles, structure.n_zeros, lags, stable, starts)
            times.append(time.perf_counter() - t0)
            fits.append(_held_out(pn, pd, plag, val_data, ts))
        truth = _held_out(num, den, lag, val_data, ts)
        ratios = [f"{t / t_ilc:.1f}" if f >= est.fit_validation - 0.5 else "n/a" for f, t in zip(fits, times)]
        print(f"{name:<34} {truth:6.2f} {est.fit_validation:7.2f} {fits[0]:6.2f} {fits[1]:6.2f} {t_ilc:8.2f}s "
              f"{times[0]:7.2f}s {times[1]:6.2f}s {ratios[0]:>6} {ratios[1]:>5}")
    print("ratio: plain time / ilcdob time where the plain fit comes within 0.5 points of ilcdob's held-out fit "
          "(n/a: it stops below)")


if __name__ == "__main__":
    main()
