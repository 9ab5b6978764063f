"""ilcdob's output-error fit against a plain one that shares no code with it.

The plain fit: every parameter of ``B(s) / (s^K A(s))`` (the delay fixed at its true whole number of samples)
moved by ``scipy.optimize.least_squares`` (trust-region reflective), the model sampled by
``scipy.signal.cont2discrete`` (zero-order hold) and simulated from rest by ``scipy.signal.lfilter``, with an
output offset; started from several denominators spread over the band (real poles at 0.3 %, 3 % and 30 % of
the Nyquist frequency, a pair at 10 % damped 0.5), the numerator of each start solved by linear least squares.
The acceptance: ilcdob's estimation fit (its initial state refitted, which only adds freedom) within 0.5 points
of the best plain start on every case, or above it. Measured (ilcdob / best plain): 90.36 / 90.35,
98.00 / 98.00, 71.65 / 71.63, 95.01 / 95.01 %.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.signal import cont2discrete, lfilter

from ilcdob.identification.oe import simulate_zoh
from ilcdob.identification.tfest import FitOptions, tfest
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure


def _simulate(num, den, ts, u, shift):
    b, a, _ = cont2discrete((np.atleast_1d(num), np.atleast_1d(den)), ts, method="zoh")
    y = lfilter(np.ravel(b), a, u)
    return np.concatenate([np.zeros(shift), y[: u.size - shift]]) if shift else y


def _fit_percent(y, yhat):
    return 100 * (1 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean()))


def _plain(structure: ModelStructure, u, y, ts, shift):
    """The best plain fit over the starts: its fit %."""
    nf, nb, k = structure.n_free_poles, structure.n_zeros + 1, structure.n_integrators
    nyq = np.pi / ts
    starts = [np.poly(np.full(nf, -f * nyq)) for f in (0.003, 0.03, 0.3)]
    if nf >= 2:
        w = 0.1 * nyq
        starts.append(np.polymul([1.0, w, w * w], np.poly(np.full(nf - 2, -w))))

    def model(theta):
        a = np.concatenate([[1.0], theta[:nf], np.zeros(k)])
        return _simulate(theta[nf:nf + nb], a, ts, u, shift) + theta[-1]

    best = -np.inf
    for a in starts:
        den = np.concatenate([a, np.zeros(k)])
        cols = [_simulate(np.eye(nb)[i], den, ts, u, shift) for i in range(nb)] + [np.ones(u.size)]
        lin, *_ = np.linalg.lstsq(np.column_stack(cols), y, rcond=None)
        x0 = np.concatenate([a[1:], lin])
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            try:
                sol = least_squares(lambda th: model(th) - y, x0, method="trf", max_nfev=400)
            except ValueError:  # a start whose simulation diverges
                continue
        fit = _fit_percent(y, model(sol.x))
        if np.isfinite(fit):
            best = max(best, fit)
    return best


def _steps(n, hold, seed):
    rng = np.random.default_rng(seed)
    return np.repeat(rng.choice([-1.0, 1.0], n // hold + 1), hold)[:n]


def _doublets(n, seed):
    rng = np.random.default_rng(seed)
    unit = np.concatenate([np.ones(30), -np.ones(30), np.zeros(140)])
    return np.concatenate([s * unit for s in rng.choice([-1.0, 1.0], n // unit.size + 1)])[:n]


CASES = {
    # structure, num, den, ts, delay in samples, input, noise AR pole, noise share of the output's spread
    "2p1z coloured noise": (ModelStructure(2, 1, 0), [2.0, 3.0], [1.0, 1.4, 4.0], 0.01, 0, ("steps", 150), 0.95, 0.1),
    "3p 2 integrators, delay": (ModelStructure(3, 0, 2), [8.0], [1.0, 8.0, 0.0, 0.0], 0.01, 4, ("doublets",), 0.0,
                                0.02),
    "flexible 4p1z": (ModelStructure(4, 1, 0), [40.0, 80.0], list(np.polymul([1, 0.4, 4], [1, 0.3, 36])), 0.05, 0,
                      ("steps", 20), 0.9, 0.3),
    "slow 2p1z, Ts 10 s": (ModelStructure(2, 1, 0), [400 / 5e4, 2 / 5e4], [1.0, 600 / 5e4, 1 / 5e4], 10.0, 3,
                           ("steps", 30), 0.0, 0.05),
}


@pytest.mark.parametrize("name", list(CASES))
def test_ilcdob_fits_at_least_as_well_as_the_best_plain_start(name):
    structure, num, den, ts, shift, excitation, pole, share = CASES[name]
    n = 3000
    u = _steps(n, excitation[1], 0) if excitation[0] == "steps" else _doublets(n, 0)
    theta = structure.join(np.asarray(num, float), np.asarray(den, float))
    clean = simulate_zoh(structure, theta, u, ts, shift * ts)
    rng = np.random.default_rng(1)
    e = lfilter([1.0], [1.0, -pole], rng.standard_normal(n))
    y = clean + share * np.std(clean) * e / np.std(e)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = tfest(FlightData(np.arange(n) * ts, {"u": u, "y": y}), "u", "y", structure,
                    FitOptions(delay=shift * ts), progress=None)
    plain = _plain(structure, u, y, ts, shift)
    assert est.fit_estimation >= plain - 0.5, (est.fit_estimation, plain)
