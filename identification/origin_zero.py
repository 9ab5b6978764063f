"""A zero fixed at s = 0: the map of a loop that integrates (docs/closed_loop.md, "A cascade that integrates").

A cascade's velocity integral (PX4, ArduPilot) cancels a constant force: the map from its acceleration
feed-forward to the position, ``G(s) = B(s)/A(s)``, has a zero at ``s = 0``, i.e. ``b0 = 0``. A free fit
puts that zero at a small ``+-eps`` (its numerator's constant ``b0`` within its noise), and a learning
filter inverting the map then has a pole at ``z = e^{eps Ts}``: just outside the unit circle it needs a
look-ahead of millions of samples, just inside it decays over hours. The physics says ``b0 = 0``.

:func:`with_zero_at_origin` imposes it on a fit by conditioning the fit's Gaussian ``N(theta, Cov)`` on
``b0 = 0``::

    theta_c = theta - Cov[:, b0] b0 / Cov[b0, b0],     Cov_c = Cov - Cov[:, b0] Cov[b0, :] / Cov[b0, b0]

which is the constrained least-squares estimate for parameters entering linearly (the numerator's do, for
a given denominator) and its first-order (Gauss-Newton) step for the others; ``Cov_c`` has no variance in
``b0``, so every map drawn from it keeps the zero. The fits and residual tests are recomputed on the
data. Refused where the data say otherwise: ``|b0|`` above ``max_sigma`` of its standard deviation.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.signals import FlightData

from .results import TFEstimate

__all__ = ["with_zero_at_origin", "ORIGIN_SIGMAS"]

#: Standard deviations of ``b0`` from 0 up to which the data are taken to allow a zero at s = 0. A loop without an
#: integral shows its ``b0`` hundreds of them away (281 for the PD loop of ``tests/test_cascade_learning.py``), a
#: cascade within a few (0.65 and 2.8 for its two): 5 refuses the first and, under the fit's noise alone, wrongly
#: refuses one cascade in 1.7 million.
ORIGIN_SIGMAS = 5.0


def _experiments(data: Sequence[FlightData], est: TFEstimate) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(u, y)`` of every piece between the gaps of ``data``, as the fit took them."""
    return [(p[est.input], p[est.output]) for fd in data for p in fd.pieces()]


def with_zero_at_origin(est: TFEstimate, data: Sequence[FlightData],
                        validation: Sequence[FlightData] | None = None,
                        max_sigma: float = ORIGIN_SIGMAS) -> TFEstimate:
    """``est`` with its numerator's constant fixed at 0 (module docstring).

    Parameters
    ----------
    est : TFEstimate
        A fit with at least one zero and no integrator.
    data : sequence of FlightData
        Its estimation data (signals named as in the fit).
    validation : sequence of FlightData, optional
        Held-out data, for the held-out fit.
    max_sigma : float
        Largest ``|b0| / std(b0)`` allowed.

    Returns
    -------
    TFEstimate
        The conditioned fit: ``num[-1] == 0``, its covariance without variance in ``b0``, its fits and
        residual tests on the data, ``solver["zero_at_origin"]`` stating ``b0`` before and its standard
        deviation.

    Raises
    ------
    SpecError
        No zero to fix, an integrator (it would cancel against the zero), ``b0`` further than ``max_sigma``
        standard deviations from 0, or a pole of the result within :data:`SLOWEST_ROOT` of the origin.
    """
    s = est.structure
    if s.n_zeros < 1:
        raise SpecError(f"`--zero-at-origin`: the model has {s.n_zeros} zeros; give at least one (--zeros 1): the "
                        "zero at s = 0 is one of them")
    if s.n_integrators:
        raise SpecError(f"`--zero-at-origin`: the model has {s.n_integrators} integrator(s); a zero at s = 0 would "
                        "cancel one: fit without them")
    i = s.n_params - 1  # b0, the last transfer-function parameter (the delay, when estimated, follows)
    cov = np.asarray(est.covariance, float)
    b0, var = float(est.theta[i]), float(cov[i, i])
    sigma = float(np.sqrt(max(var, 0.0)))
    if not (sigma > 0 and abs(b0) <= max_sigma * sigma):
        z = abs(b0) / sigma if sigma > 0 else np.inf
        raise SpecError(f"`--zero-at-origin`: the fit's b0 = {b0:.4g} is {z:.3g} standard deviations ({sigma:.3g}) "
                        f"from 0, beyond {max_sigma:g}: the data show no zero at "
                        "s = 0 (a loop without an integral on this channel); fit without --zero-at-origin")
    full = np.concatenate([est.theta, [est.delay]]) if est.delay_estimated else np.asarray(est.theta, float)
    full = full - cov[:, i] * (b0 / var)
    full[i] = 0.0
    cov_c = cov - np.outer(cov[:, i], cov[i, :]) / var
    cov_c[i, :] = cov_c[:, i] = 0.0
    theta = full[: s.n_params]
    from ilcdob.channel_loop import SLOWEST_ROOT  # here: the channel loop's python-control stays unloaded

    slow = [p for p in np.roots(s.split(theta)[0]) if abs(p) < SLOWEST_ROOT]
    if slow:
        raise SpecError(f"`--zero-at-origin`: the fit puts a pole at s = {complex(slow[0]):.3g} beside the zero at "
                        "s = 0, cancelling it: the data show a loop without an integral on this channel; fit without "
                        "--zero-at-origin")
    delay = max(0.0, float(full[-1])) if est.delay_estimated else est.delay
    solver = {**est.solver, "zero_at_origin": {"b0_fitted": b0, "b0_std": sigma,
                                               "rule": "b0 = 0 by conditioning N(theta, Cov) on it "
                                                       "(identification/origin_zero.py)"}}
    return TFEstimate.from_fit(structure=s, theta=theta, delay=delay, covariance=cov_c,
                               delay_estimated=est.delay_estimated, sigma2=est.sigma2,
                               experiments=_experiments(data, est), ts=est.ts,
                               validation=list(validation) if validation else None, input=est.input,
                               output=est.output, solver=solver, trend=est.trend)
