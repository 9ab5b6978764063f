"""Fitting several model orders and choosing among them (docs/identification.md, "Orders").

A structure with ``p`` more poles and ``z`` more zeros than another (the same integrators) contains it: a
pole-zero pair that cancels, a pole so fast or a zero so far that the sampled response cannot tell it
from a constant. Fitted from its own starts alone, the larger structure can still end in a local minimum
worse than the smaller model it contains (estimation fit 77.3 % with five poles where four reached 82.5 %).
So each order is also started from the best fit it contains, extended by those factors
(:func:`nested_start`), and keeps the better of the two runs: its estimation fit is then never below that
of an order it contains (to the stopping tolerance of its search).

The choice (:func:`compare_orders`): with held-out data, the fewest parameters within
:data:`ORDER_FIT_MARGIN` points of the best held-out fit; without, the lowest AIC; a model with a pole
the data cannot show (beyond the Nyquist frequency, or a mode damped less than
:data:`~ilcdob.identification.results.MARGINAL_DAMPING`) is chosen only when every order has one.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Callable, Sequence

import numpy as np

from ilcdob.uncertainty import ModelStructure

from .results import TFEstimate, unidentified_poles

__all__ = ["ORDER_FIT_MARGIN", "FAR_FACTOR", "contains", "nested_start", "fit_orders", "compare_orders"]

#: Held-out fit (points) within which the order with fewer parameters is chosen (:func:`compare_orders`).
ORDER_FIT_MARGIN = 0.5
#: An added pole (or zero) of :func:`nested_start` sits this many times the Nyquist frequency out: it lags the
#: response by ``Ts / (pi FAR_FACTOR)``, 0.3 % of a sample (at 10 times, 3 %, the larger order started up to
#: 2e-3 points below the smaller one and stayed there; at 100 times within 1e-6 points).
FAR_FACTOR = 100.0


def contains(big: ModelStructure, small: ModelStructure) -> bool:
    """Whether ``big`` holds every model of ``small`` (as a limit): as many integrators, at least as many
    poles and zeros, and not the same structure.

    Parameters
    ----------
    big, small : ModelStructure

    Returns
    -------
    bool
    """
    dp, dz = big.n_poles - small.n_poles, big.n_zeros - small.n_zeros
    return big.n_integrators == small.n_integrators and dp >= 0 and dz >= 0 and dp + dz > 0


def nested_start(small: TFEstimate, big: ModelStructure) -> np.ndarray:
    """``small``'s model written in ``big``'s parameters (module docstring): ``min(p, z)`` pole-zero pairs
    that cancel, at the geometric mean of the model's pole magnitudes; ``p - z`` poles at
    ``FAR_FACTOR`` times the Nyquist frequency with the gain kept; ``z - p`` zeros as far out.

    Parameters
    ----------
    small : TFEstimate
        The contained fit.
    big : ModelStructure
        The containing structure (:func:`contains`).

    Returns
    -------
    numpy.ndarray
        ``big``'s ``theta`` (free denominator, then numerator).

    Raises
    ------
    ValueError
        ``big`` does not contain ``small.structure``.
    """
    s = small.structure
    if not contains(big, s):
        raise ValueError(f"`big`: {big} does not contain {s}")
    dp, dz = big.n_poles - s.n_poles, big.n_zeros - s.n_zeros
    far = FAR_FACTOR * np.pi / small.ts
    roots = np.roots(np.asarray(small.den, float)[: s.n_free_poles + 1]) if s.n_free_poles else np.zeros(0)
    mid = float(np.exp(np.mean(np.log(np.abs(roots))))) if roots.size and np.all(roots != 0) else 0.1 * far
    pair = min(dp, dz)
    a = np.polymul(np.asarray(small.den, float)[: s.n_free_poles + 1],
                   np.polymul(np.poly(np.full(pair, -mid)), np.poly(np.full(dp - pair, -far))))
    b = np.polymul(np.asarray(small.num, float) * far ** (dp - pair),
                   np.polymul(np.poly(np.full(pair, -mid)), np.poly(np.full(dz - pair, -far)) / far ** (dz - pair)))
    return big.join(np.real(b), np.concatenate([np.real(a), np.zeros(s.n_integrators)]))


def fit_orders(fit: Callable[[ModelStructure, Any], TFEstimate], structures: Sequence[ModelStructure],
               options: Any) -> list[TFEstimate]:
    """Fit every structure, each also from the best fit it contains (module docstring).

    Parameters
    ----------
    fit : callable
        ``fit(structure, options) -> TFEstimate`` (e.g. :func:`~ilcdob.identification.tfest.tfest` on the data).
    structures : sequence of ModelStructure
        The orders, in any order (fitted fewest parameters first).
    options : FitOptions
        The fit settings; the nested run replaces only their ``initial``.

    Returns
    -------
    list of TFEstimate
        One per structure, in the order given; ``solver["nested_start"]`` names the contained structure a fit
        started from where that run won.
    """
    order = sorted(range(len(structures)), key=lambda i: (structures[i].n_params, structures[i].n_poles))
    fits: dict[int, TFEstimate] = {}
    for i in order:
        st = structures[i]
        est = fit(st, options)
        inner = [fits[k] for k in fits if contains(st, structures[k])]
        if inner and options.initial is None:
            best = max(inner, key=lambda e: e.fit_estimation)
            nested = fit(st, replace(options, initial=tuple(nested_start(best, st))))
            if nested.fit_estimation > est.fit_estimation:
                b = best.structure
                nested.solver["nested_start"] = f"{b.n_poles} poles, {b.n_zeros} zeros, {b.n_integrators} integrators"
                est = nested
        fits[i] = est
    return [fits[i] for i in range(len(structures))]


def compare_orders(fits: Sequence[TFEstimate], n_samples: int) -> TFEstimate:
    """Choose among fits of several orders and record the comparison (module docstring).

    Each row: poles, zeros, integrators, parameter count ``k`` (with the delay when estimated),
    estimation and held-out fit %, ``AIC = N ln(sigma^2) + 2 k`` (``N`` estimation samples) and the poles
    the data cannot show (:func:`~ilcdob.identification.results.unidentified_poles`).

    Parameters
    ----------
    fits : sequence of TFEstimate
        One per order.
    n_samples : int
        Estimation samples.

    Returns
    -------
    TFEstimate
        The chosen fit, with ``solver["order_comparison"]`` (the rows, ``chosen`` marked).
    """
    rows = []
    for est in fits:
        k = est.structure.n_params + (1 if est.delay_estimated else 0)
        rows.append({"poles": est.structure.n_poles, "zeros": est.structure.n_zeros,
                     "integrators": est.structure.n_integrators, "parameters": k,
                     "fit_estimation": est.fit_estimation, "fit_validation": est.fit_validation,
                     "aic": float(n_samples * np.log(max(est.sigma2, 1e-300)) + 2 * k),
                     "not_identified": unidentified_poles(est), "chosen": False})
    shown = [i for i, r in enumerate(rows) if not r["not_identified"]] or list(range(len(rows)))
    if all(rows[i]["fit_validation"] is not None for i in shown):
        best = max(rows[i]["fit_validation"] for i in shown)
        pick = min((i for i in shown if rows[i]["fit_validation"] >= best - ORDER_FIT_MARGIN),
                   key=lambda i: rows[i]["parameters"])
    else:
        pick = min(shown, key=lambda i: rows[i]["aic"])
    rows[pick]["chosen"] = True
    chosen = fits[pick]
    chosen.solver["order_comparison"] = rows
    return chosen
