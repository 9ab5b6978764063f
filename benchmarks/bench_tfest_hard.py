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

Then the start search: every case above and five of ``tests/test_tfest_hard.py`` (coloured noise,
slow drift with a trend, offsets and initial conditions, closed loop with delay and saturation, a
logger dropout), at the tests' lengths and ``--scales`` times as long, fitted with the former start
search (``bench_tfest.baseline_candidates``) and the shipped one, interleaved: held-out fit of each,
the largest parameter difference in standard deviations, the criterion difference, the decimation
of the ranking record and the CPU-time ratio.

Run:  python benchmarks/bench_tfest_hard.py [--search-only] [--scales 1 8] [--repeat 3]
"""

from __future__ import annotations

import argparse
import importlib
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import control as ct
import numpy as np
from scipy import optimize
from scipy import signal as sps

from ilcdob.identification.results import fit_percent
from ilcdob.identification.tfest import FitOptions, tfest
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure

sys.path.insert(0, str(Path(__file__).resolve().parent))   # bench_tfest: the baseline start search


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
    return [structure.split(p.theta) for p in tf._candidates(model, 0.0, tf._silent)[0][: opts.starts]]


def _flexible(scale: int = 1):
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
        u = np.repeat(rng.standard_normal(300 * scale + 1), 20)[:6000 * scale]
        y = _simulate(num, den, u, ts, 0)
        data.append((u, y + 0.02 * np.std(y) * rng.standard_normal(u.size)))
    return "flexible (6 poles, 5 zeros)", ts, num, den, 0, data[:1], data[1:], ModelStructure(6, 5, 0), FitOptions(), \
        [0], True


def _thermal(scale: int = 1):
    num, den, ts, data = np.array([1.0]), np.polymul([60.0, 1.0], [15.0, 1.0]), 2.0, []
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        u = np.repeat(rng.choice([-1.0, 1.0], 60 * scale + 1), 60)[:3600 * scale]
        data.append((u, _simulate(num, den, u, ts, 6) + 0.01 * rng.standard_normal(u.size)))
    return ("thermal (2 poles, 12 s delay, Ts 2 s)", ts, num, den, 6, data[:1], data[1:], ModelStructure(2, 0, 0),
            FitOptions(delay="auto"), list(range(0, 16)), True)


def _unstable(scale: int = 1):
    p = ct.tf([2.0], np.polymul([1.0, -0.5], [1.0, 3.0]))
    ts, n, data = 0.01, 3000 * scale, []
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


def _lagging(scale: int = 1):
    num, den, data = _stable_files((3, 4), np.random.default_rng(3), n=3000 * scale)
    late = [(u[:-5], y[5:]) for u, y in data]               # the input logged 5 samples late
    return ("lagging input (5 samples late)", 0.01, num, den, 0, late[:1], late[1:], ModelStructure(2, 1, 0),
            FitOptions(delay="auto", max_delay=0.15), list(range(0, 16)), True)


def _corrupt(scale: int = 1):
    rng = np.random.default_rng(21)
    n = 3000 * scale
    num, den, files = _stable_files(range(4), rng, n=n)
    files[2] = (files[2][0], files[2][1] + np.where(np.arange(n) >= n - 100, 16.0, 0.0))
    return ("corrupt file among four", 0.01, num, den, 0, files, _stable_files((7,), rng, n=n)[2],
            ModelStructure(2, 1, 0), FitOptions(), [0], True)


def _held_out(num, den, lag, val, ts) -> float:
    yhat = [_simulate(num, den, u, ts, lag) for u, _ in val]
    y = np.concatenate([y for _, y in val])
    return fit_percent(y, np.concatenate([yh + np.mean(yv - yh) for yh, (_, yv) in zip(yhat, val)]))


# ---------------------------------------------------------------- the start search: baseline against shipped

def _excite(n: int, seed: int, ts: float, doublets: bool = False) -> np.ndarray:
    """Chirp plus random steps, or (integrating plants) a cosine chirp plus doublets (as in the tests)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * ts
    if not doublets:
        chirp = np.sin(2 * np.pi * (0.05 * t + 3.0 * t**2 / (2 * t[-1])))
        return 0.7 * chirp + 0.5 * np.repeat(rng.choice([-1.0, 1.0], n // 150 + 1), 150)[:n]
    unit = np.concatenate([np.ones(30), -np.ones(30), np.zeros(140)])
    d = np.concatenate([sg * unit for sg in rng.choice([-1.0, 1.0], n // unit.size + 1)])[:n]
    return 0.3 * np.cos(2 * np.pi * (0.3 * t + 2.0 * t**2 / (2 * t[-1]))) + 1.5 * d


_STABLE = (ModelStructure(2, 1, 0), [2.0, 3.0], [1.0, 1.4, 4.0])
_QUAD = (ModelStructure(3, 0, 2), [8.0], [1.0, 8.0, 0.0, 0.0])


def _suite_case(name: str, scale: int):
    """Cases of ``tests/test_tfest_hard.py`` (coloured noise, drift, offsets and initial conditions, closed
    loop with delay and saturation, a logger dropout), ``scale`` times as long: ``(estimation, validation,
    structure, options)``."""
    from ilcdob.identification.oe import simulate_zoh
    from ilcdob.identification.synthetic import closed_loop_flight
    from ilcdob.specs import PIDSpec, PlantSpec

    ts = 0.01
    structure, num, den = _QUAD if name in ("closed loop, delay, saturation", "logger dropout") else _STABLE
    theta = structure.join(num, den)

    def flight(u, y, **meta):
        return FlightData(np.arange(u.size) * ts, {"u": u, "y": y}, metadata=meta)

    flights, opts = [], FitOptions()
    if name == "coloured noise":
        rng = np.random.default_rng(1)
        for seed in (0, 1):
            u = _excite(4000 * scale, seed, ts)
            y0 = simulate_zoh(structure, theta, u, ts)
            w = sps.lfilter([1.0], [1.0, -0.97], rng.standard_normal(u.size))
            flights.append(flight(u, y0 + 0.15 * np.std(y0) * w / np.std(w)))
    elif name == "slow drift (trend 3)":
        rng = np.random.default_rng(2)
        for seed in (0, 1):
            u = _excite(5000 * scale, seed, ts)
            t = np.arange(u.size) * ts
            drift = 0.8 * t / t[-1] + 0.4 * np.sin(2 * np.pi * t / 90.0 + seed)
            y = simulate_zoh(structure, theta, u, ts) + drift + 0.02 * rng.standard_normal(u.size)
            flights.append(flight(u, y))
        opts = FitOptions(trend=3)
    elif name == "offsets, initial conditions":
        rng = np.random.default_rng(3)
        for seed, (x0, offset) in enumerate((([1.5, -2.0], 3.7), ([-0.8, 0.6], -1.2), ([0.3, 2.5], 0.4))):
            u = _excite(3000 * scale, seed, ts)
            y = simulate_zoh(structure, theta, u, ts, x0=np.array(x0)) + offset
            flights.append(flight(u, y + 0.02 * rng.standard_normal(u.size)))
        return flights[:2], flights[2:], structure, opts
    elif name == "closed loop, delay, saturation":
        rng = np.random.default_rng(6)
        for seed in (0, 1):
            n = 4000 * scale
            t = np.arange(n) * ts
            r = np.repeat(np.random.default_rng(seed).choice([-0.6, 0.6], n // 300 + 1), 300)[:n]
            r = r + 0.2 * np.sin(2 * np.pi * (0.05 * t + 1.5 * t**2 / (2 * t[-1])))
            noise = 2e-3 * rng.standard_normal(n)
            u, y = closed_loop_flight(PlantSpec(num, den, 0.02), PIDSpec(3.0, 0.3, 0.12, 0.05), r, ts, noise, 1.2)
            flights.append(flight(u, y + noise))
        opts = FitOptions(delay="auto", max_delay=0.1)
    elif name == "logger dropout":
        rng = np.random.default_rng(9)
        for seed in (0, 1):
            n = 4000 * scale
            u = _excite(n, seed, ts, doublets=True)
            y = simulate_zoh(structure, theta, u, ts) + 1e-3 * rng.standard_normal(n)
            flights.append(flight(u, y, gaps=[[15.0, 16.5]]))     # cut there: FlightData.pieces()
    else:
        raise ValueError(f"_suite_case: got {name!r}")
    return flights[:1], flights[1:], structure, opts


SUITE = ("coloured noise", "slow drift (trend 3)", "offsets, initial conditions", "closed loop, delay, saturation",
         "logger dropout")


def _all_cases(scale: int):
    for case in (_flexible, _thermal, _unstable, _lagging, _corrupt):
        name, ts, _, _, _, est_data, val_data, structure, opts, _, _ = case(scale)
        yield (name, [FlightData(np.arange(u.size) * ts, {"u": u, "y": y}, source=f"file {i + 1}")
                      for i, (u, y) in enumerate(est_data)],
               [FlightData(np.arange(u.size) * ts, {"u": u, "y": y}) for u, y in val_data], structure, opts)
    for name in SUITE:
        yield (name, *_suite_case(name, scale))


def compare_search(scales: list[int], repeat: int) -> list[dict]:
    """Every case fitted with today's start search (``bench_tfest.baseline_candidates``) and the shipped one,
    interleaved (baseline, shipped, baseline, ...), ``repeat`` times each: CPU time medians, held-out fit %,
    the largest parameter difference in units of the baseline's standard deviations, the relative criterion
    difference and the decimation the shipped search ranked on."""
    from bench_tfest import search

    rows = []
    for scale in scales:
        for name, est_data, val_data, structure, opts in _all_cases(scale):
            times, ests = {"baseline": [], "new": []}, {}
            for _ in range(repeat):
                for which in ("baseline", "new"):
                    with search(which), warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        t0 = time.process_time()
                        ests[which] = tfest(est_data, "u", "y", structure, opts, validation=val_data, progress=None)
                        times[which].append(time.process_time() - t0)
            b, n = ests["baseline"], ests["new"]
            tb = np.concatenate([b.theta, [b.delay]]) if b.delay_estimated else b.theta
            tn = np.concatenate([n.theta, [n.delay]]) if n.delay_estimated else n.theta
            with np.errstate(divide="ignore", invalid="ignore"):
                d_sigma = float(np.max(np.abs(tn - tb) / b.std))
            rows.append({"case": name, "scale": scale, "samples": sum(fd.t.size for fd in est_data),
                         "decimation": n.solver.get("ranking", {}).get("decimation", 1),
                         "fit_baseline": b.fit_validation, "fit_new": n.fit_validation, "theta_baseline": tb,
                         "theta_new": tn, "d_sigma": d_sigma, "d_sse": n.sigma2 / b.sigma2 - 1.0,
                         "t_baseline": statistics.median(times["baseline"]), "t_new": statistics.median(times["new"])})
            r = rows[-1]
            print(f"{name:<36} {scale:>2}x {r['samples']:>7} {r['decimation']:>4} {r['fit_baseline']:8.3f} "
                  f"{r['fit_new']:8.3f} {r['d_sigma']:9.2e} {r['d_sse']:+9.1e} {r['t_baseline'] * 1e3:9.1f} "
                  f"{r['t_new'] * 1e3:8.1f} {r['t_baseline'] / r['t_new']:6.2f}", flush=True)
    return rows


def plain_comparison() -> None:
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--search-only", action="store_true", help="only the start-search comparison")
    parser.add_argument("--scales", type=int, nargs="+", default=[1, 8],
                        help="record lengths of the start-search comparison, in multiples of the tests' (1 8)")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved runs per search and case (3)")
    args = parser.parse_args()
    if not args.search_only:
        plain_comparison()
    print(f"\nstart search: baseline (every candidate solved on the whole record) against shipped (ranked on the "
          f"band-limited decimated record, batched); median CPU time of {args.repeat} interleaved runs; "
          f"load {os.getloadavg()[0]:.2f}")
    print(f"{'case':<36} {'len':>3} {'samples':>7} {'dec':>4} {'fit base':>8} {'fit new':>8} {'dθ/σ':>9} "
          f"{'dSSE':>9} {'t base ms':>9} {'t new ms':>8} {'ratio':>6}")
    compare_search(args.scales, args.repeat)
    print("fit: held-out fit %; dθ/σ: largest parameter (and delay) difference in the baseline's standard "
          "deviations; dSSE: relative criterion difference (new / baseline - 1); ratio: baseline time / shipped time")


if __name__ == "__main__":
    main()
