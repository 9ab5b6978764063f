"""Whole-trial improvement of a learning law: the lifted ``N``-sample error map (docs/theory.md sections 2, 3, 6).

The improvement guarantees of the designs are stated per frequency (:mod:`..methods.robust_set`): for a
signal over an infinite horizon, ``||e_j|| <= rho ||e'_j||``. A trial has ``N`` samples. On it,
with the disturbance ``d`` (the same at both vehicles) and the learning law ``L`` of
:meth:`~ilcdob.design.pair.PairDesign.learning` (band fixed, no limit, the paper's law, one trial
of the source without learning), the two errors are linear in ``d``::

    e'_j = B d,   B = -Gd_j                         (vehicle j without learning)
    e_j  = A d,   A = -Gd_j + Gf_j L Gd_{j-1}        (with d_f,j = L{e'_{j-1}}, e'_{j-1} = -Gd_{j-1} d)

with ``Gd``, ``Gf`` the loops' lower-triangular Toeplitz (lifted, causal, from rest) maps of the
*true* plants and ``L`` the law as it runs on a trial (its extensions past the trial's ends, its
non-causal filters, the fold at the start; all linear). The whole-trial figure is the
generalised Rayleigh quotient::

    rho_N = max_d ||A d|| / ||B d||

What is excluded. ``B`` has an (almost) null space that no law can be judged on: the last
``r`` samples of ``d`` (``r``: the relative degree of ``Gd_j`` in samples) never reach ``e'_j``
within the trial, and for each zero ``z`` of ``Gd_j`` outside the unit circle (the ZOH sampling
zero of a relative-degree-3 plant, ``z ~ -3.6``) the disturbance ``d[k] = z^(k - N + 1 + r)``
grows into the trial's last samples and leaves ``e'_j`` at ``~|z|^-N`` of its size (``1e-22`` at
``N = 300``). Any law that learns at all answers such a ``d`` (the source's zero differs), so
``max ||A d|| / ||B d||`` over all of ``R^N`` is unbounded (``6e9`` at ``N = 300`` for the exact
closed form). ``rho_N`` is the maximum over the disturbances orthogonal to these ``r + (number of
such zeros)`` directions (:func:`invisible_disturbances`); the directions are listed with it.

How it is computed. Every map is applied as a filter, ``O(N log N)`` per product, with its
adjoint (time-reversed filtering; :class:`LinearMap`): the loops by their Markov parameters, the
law by :func:`law_map` (closed form and robust-set designs, with or without their band). The
quotient is the largest eigenvalue of the pencil ``(A^T A, B^T B)`` restricted to the admissible
disturbances, found by ARPACK (``scipy.sparse.linalg.eigsh``, Lanczos) with ``B^T B`` solved by
conjugate gradients preconditioned with the stable inversion of ``Gd_j``
(:func:`~ilcdob.design.maps.closed_form.inverse_gd_filter`), which makes the pencil well conditioned
although ``B`` alone has a condition number of about ``1e5`` (``|Gd_j|`` at Nyquist).
:func:`law_map` is checked against :meth:`~ilcdob.design.pair.PairDesign.learning` and the
adjoints by the dot-product test (``tests/test_finite_horizon.py``).

Structural result (built-in fleet, exact models, 60 s; :mod:`..methods.robust_set`). A law whose filters
act causally on the reconstructed disturbance keeps its per-frequency bound on every finite
trial (causal lifted maps commute, so ``e_j = (1 - F R) e'_j`` exactly on the trial, up to the
stable inversion's last samples): the closed form without a band has ``rho_N`` = 0.0019 / 0.012 /
0.014 (UAV1 -> UAV2, UAV2 -> UAV3, UAV3 -> UAV1); a causal robust-set filter (``advance = 0``) at
most its nominal ``max |1 - F|`` plus that end term. A zero-phase (non-causal) filter cannot: a
disturbance at an end of the trial is spread by it to times where ``e'_j`` has nothing, and
``rho_N > 1`` for every such filter: the 301-tap robust-set filter 1.5-2.1 at |Delta| <= 0.3 and
0.5 with its trial-end treatment (750-25000 with ``d_hat`` held past the end), the worst ``d`` in
the trial's last second; the closed form through a 10 rad/s band 1.96, the worst ``d`` at the
start.
"""

from __future__ import annotations

import copy
import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import control as ct
import numpy as np
from scipy import signal as sps
from scipy.signal import fftconvolve
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, cg, eigsh

from ilcdob.errors import NumericalError, SpecError
from ilcdob.lifted import markov_parameters
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal

from ..filters.band import fade_out
from .closed_form import LearningFilters, inverse_gd_filter
from ..filters.noncausal import ZPKFilter, lookahead
from ..filters.trial_edges import StartMatch, trend_weights

__all__ = ["LinearMap", "identity_map", "causal_map", "sos_map", "zpk_map", "fir_map",
           "trend_map", "odd_start_map", "extension_map", "crop_map", "fold_map", "law_map", "error_maps", "invisible_disturbances", "FiniteHorizonRatio",
           "finite_horizon_ratio", "PairTrials"]

_CUBIC_FIT = 16  # samples extend_smoothly fits its cubic to (ilcdob.signals.extend_smoothly default)


@dataclass(frozen=True)
class LinearMap:
    """A linear map ``R^n_in -> R^n_out`` given by its product and its adjoint's.

    Attributes
    ----------
    n_in, n_out : int
        Dimensions.
    fwd : callable
        ``x -> M x``.
    adj : callable
        ``y -> M^T y``.
    name : str
        What it is (messages).
    """

    n_in: int
    n_out: int
    fwd: Callable[[np.ndarray], np.ndarray] = field(repr=False)
    adj: Callable[[np.ndarray], np.ndarray] = field(repr=False)
    name: str = ""

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.fwd(np.asarray(x, float))

    def T(self, y: np.ndarray) -> np.ndarray:  # noqa: N802 - the adjoint, as in linear algebra
        """The adjoint's product ``M^T y``.

        Parameters
        ----------
        y : array
            ``n_out`` values.
        """
        return self.adj(np.asarray(y, float))

    def __matmul__(self, other: "LinearMap") -> "LinearMap":
        if other.n_out != self.n_in:
            raise SpecError(f"composing {self.name} ({self.n_in} inputs) with {other.name} ({other.n_out} outputs)")
        return LinearMap(other.n_in, self.n_out, lambda x: self.fwd(other.fwd(x)), lambda y: other.adj(self.adj(y)),
                         f"{self.name} {other.name}")

    def __add__(self, other: "LinearMap") -> "LinearMap":
        if (other.n_in, other.n_out) != (self.n_in, self.n_out):
            raise SpecError(f"adding {self.name} and {other.name} of different shapes")
        return LinearMap(self.n_in, self.n_out, lambda x: self.fwd(x) + other.fwd(x),
                         lambda y: self.adj(y) + other.adj(y), f"({self.name} + {other.name})")

    def __neg__(self) -> "LinearMap":
        return LinearMap(self.n_in, self.n_out, lambda x: -self.fwd(x), lambda y: -self.adj(y), f"-{self.name}")

    def matrix(self) -> np.ndarray:
        """The dense matrix (``n_in`` products; for checks on short trials)."""
        return np.column_stack([self.fwd(col) for col in np.eye(self.n_in)])


def _rev(x: np.ndarray) -> np.ndarray:
    return x[::-1]


def identity_map(n: int, name: str = "I") -> LinearMap:
    """The identity over ``n`` samples.

    Parameters
    ----------
    n : int
        Samples.
    name : str
        Its name.
    """
    return LinearMap(n, n, lambda v: v, lambda v: v, name)


def causal_map(sys: ct.StateSpace | np.ndarray, n: int, name: str = "G") -> LinearMap:
    """A causal discrete SISO map from rest over ``n`` samples (lower-triangular Toeplitz).

    Parameters
    ----------
    sys : control.StateSpace or array
        The system, or its first ``n`` Markov parameters.
    n : int
        Samples.
    name : str
        Its name.
    """
    h = np.asarray(sys, float) if isinstance(sys, np.ndarray) else markov_parameters(sys, n)
    h = h[:n]

    def fwd(x: np.ndarray) -> np.ndarray:
        return fftconvolve(h, x)[:n]

    def adj(y: np.ndarray) -> np.ndarray:
        return _rev(fftconvolve(h, _rev(y))[:n])

    return LinearMap(n, n, fwd, adj, name)


def sos_map(sos: np.ndarray, n: int, name: str = "sos") -> LinearMap:
    """Second-order sections run causally from rest over ``n`` samples (``scipy.signal.sosfilt``).

    Parameters
    ----------
    sos : array
        Sections ``[b0, b1, b2, 1, a1, a2]``.
    n : int
        Samples.
    name : str
        Its name.
    """
    sos = np.asarray(sos, float)
    return LinearMap(n, n, lambda x: sps.sosfilt(sos, x), lambda y: _rev(sps.sosfilt(sos, _rev(y))), name)


def _poly_tail(m: int, deg: int, n_pad: int, weights: np.ndarray | None = None) -> np.ndarray:
    """``n_pad x m`` matrix: the least-squares polynomial of degree ``deg`` through ``m`` samples
    (squared residuals weighted by ``weights``), evaluated at the ``n_pad`` samples after them (what
    ``numpy.polyfit(..., w=sqrt(weights))`` + ``polyval`` give)."""
    k = np.arange(m, dtype=float)
    v = np.vander(k, deg + 1)
    ve = np.vander(np.arange(m, m + n_pad, dtype=float), deg + 1)
    if weights is None:
        return ve @ np.linalg.pinv(v)
    sw = np.sqrt(np.asarray(weights, float))
    return ve @ np.linalg.pinv(sw[:, None] * v) * sw[None, :]


def extension_map(n: int, n_before: int, n_after: int, n_fit: int, deg: int) -> LinearMap:
    """``x -> [zeros(n_before), x, polynomial tail of n_after samples]`` and its adjoint.

    Parameters
    ----------
    n : int
        Samples of ``x``.
    n_before, n_after : int
        Samples added before and after.
    n_fit : int
        Last samples the tail's least-squares polynomial is fitted to.
    deg : int
        Its degree (lower when ``x`` is shorter).
    """
    m = min(n_fit, n)
    deg = min(deg, m - 1)
    e = _poly_tail(m, deg, n_after) if n_after > 0 and deg >= 0 else np.zeros((n_after, m))
    n_out = n_before + n + n_after

    k, after = np.arange(m, dtype=float), np.arange(m, m + n_after, dtype=float)

    def fwd(x: np.ndarray) -> np.ndarray:  # numpy.polyfit as the filters' own continuations run it, to the bit
        tail = np.polyval(np.polyfit(k, x[n - m:], deg) if deg > 0 else x[n - 1:], after) if n_after else after
        return np.concatenate([np.zeros(n_before), x, tail])

    def adj(y: np.ndarray) -> np.ndarray:
        out = y[n_before:n_before + n].copy()
        out[n - m:] += e.T @ y[n_before + n:]
        return out

    return LinearMap(n, n_out, fwd, adj, "H")


def crop_map(n_in: int, start: int, n: int) -> LinearMap:
    """``x -> x[start:start + n]``.

    Parameters
    ----------
    n_in : int
        Samples of ``x``.
    start : int
        First sample kept.
    n : int
        Samples kept.
    """
    def adj(y: np.ndarray) -> np.ndarray:
        out = np.zeros(n_in)
        out[start:start + n] = y
        return out

    return LinearMap(n_in, n, lambda x: x[start:start + n].copy(), adj, "crop")


def fold_map(pad: int, n: int, fold: bool = True) -> LinearMap:
    """``n + 2 pad -> n``: :func:`~..filters.band.fold_start`.

    Parameters
    ----------
    pad : int
        Samples before and after the trial.
    n : int
        Samples of the trial.
    fold : bool
        Add the part before ``t = 0``, time-reversed, to the first samples (False: crop only).
    """
    m = min(pad, n) if fold else 0

    def fwd(z: np.ndarray) -> np.ndarray:
        out = z[pad:pad + n].copy()
        if m:
            out[:m] += z[pad - m:pad][::-1]
        return out

    def adj(y: np.ndarray) -> np.ndarray:
        out = np.zeros(n + 2 * pad)
        out[pad:pad + n] = y
        if m:
            out[pad - m:pad] += y[:m][::-1]
        return out

    return LinearMap(n + 2 * pad, n, fwd, adj, "fold")


def zpk_map(f: ZPKFilter, n: int) -> LinearMap:
    """:meth:`ZPKFilter.apply <ilcdob.design.filters.noncausal.ZPKFilter.apply>` over ``n`` samples as a linear map.

    The filter as applied (:attr:`~ilcdob.design.filters.noncausal.ZPKFilter.realised`): the trial with a
    lead of zeros (the anti-causal part's look-ahead) and continued by the cubic of
    :func:`~ilcdob.signals.extend_smoothly` (advance + 8 + that look-ahead samples), the anti-causal
    poles run backwards, the causal part forwards, the advance cropped.

    Parameters
    ----------
    f : ZPKFilter
        The filter.
    n : int
        Samples of the trial.
    """
    g = f.realised
    k = g.advance
    pu = g.anticausal_poles
    n_pad, n_pre = k + 8, 0
    if len(pu):
        n_pre = max(lookahead(p) for p in pu)
        n_pad += n_pre
    ext = extension_map(n, n_pre, n_pad, _CUBIC_FIT, 3)
    n_ext = ext.n_out
    maps = [ext]
    if len(pu):
        sos_u = sps.zpk2sos(np.zeros(len(pu)), 1.0 / pu, 1.0)
        scale = float(np.real(np.prod(-1.0 / pu)))
        maps.append(LinearMap(n_ext, n_ext, lambda x: scale * _rev(sps.sosfilt(sos_u, _rev(x))),
                              lambda y: scale * sps.sosfilt(sos_u, y), "anti-causal"))
    pc = np.concatenate([g.causal_poles, np.zeros(k)])
    maps.append(sos_map(sps.zpk2sos(g.zeros, pc, g.gain), n_ext, "causal"))
    maps.append(crop_map(n_ext, n_pre + k, n))
    out = maps[0]
    for mp in maps[1:]:
        out = mp @ out
    return LinearMap(n, n, out.fwd, out.adj, "zpk")


def fir_map(h: np.ndarray, advance: int, n: int, fold: bool = True, n_in: int | None = None,
            start: StartMatch | None = None) -> LinearMap:
    """``out[k] = sum_i h[i] x[k + advance - i]``, ``k < n``, with ``x = 0`` before ``t = 0`` and after its
    ``n_in`` samples (default ``n``; more: the input's continuation past the trial); the output before
    ``t = 0`` replaced by ``start``'s continuation over the first samples, or with ``fold`` (and no
    ``start``) added time-reversed to them (:meth:`RobustSetDesign.apply
    <ilcdob.design.methods.robust_set.RobustSetDesign.apply>`).

    Parameters
    ----------
    h : array
        Taps.
    advance : int
        Non-causal lead, samples.
    n : int
        Output samples (the trial).
    fold : bool
        Fold the output before ``t = 0`` onto the first samples.
    n_in : int, optional
        Input samples (default ``n``).
    start : StartMatch, optional
        :class:`~ilcdob.design.filters.trial_edges.StartMatch` of the law (``advance`` >= 1).
    """
    h = np.asarray(h, float)
    a = int(advance)
    L = h.size
    n_x = n if n_in is None else int(n_in)
    big_n = n_x + L - 1  # length of the full convolution; output time k sits at index k + a
    m = min(a, n) if fold and start is None else 0
    k_start = start.matrix(a)[:n] if start is not None and a else None  # (span, a): the part before t = 0 -> start

    def fwd(x: np.ndarray) -> np.ndarray:
        full = np.convolve(x, h)
        out = np.zeros(n)
        hi = min(a + n, big_n)
        out[:hi - a] = full[a:hi]
        if m:
            out[:m] += full[a - m:a][::-1]
        if k_start is not None:
            out[:k_start.shape[0]] += k_start @ full[:a]
        return out

    def adj(y: np.ndarray) -> np.ndarray:
        big = np.zeros(big_n)
        hi = min(a + n, big_n)
        big[a:hi] = y[:hi - a]
        if m:
            big[a - m:a] += y[:m][::-1]
        if k_start is not None:
            big[:a] += k_start.T @ y[:k_start.shape[0]]
        return np.correlate(big, h, "valid")[:n_x]

    return LinearMap(n_x, n, fwd, adj, "FIR")


def trend_map(n: int, advance: int, fade: int) -> LinearMap:
    """:func:`~ilcdob.design.filters.trial_edges.end_continuation` as a linear map ``n -> n + advance``.

    Parameters
    ----------
    n : int
        Samples of the trial.
    advance : int
        Samples the trend continues past its end.
    fade : int
        Samples at the end blended into the trend.
    """
    m = min(int(fade), n)
    fit = min(2 * int(advance), n - m)
    n_line = m + int(advance)
    if fit >= 2:  # the weighted line through the fit window, at the m + advance samples after it
        e = _poly_tail(fit, 1, n_line, trend_weights(fit))
    else:
        e = np.zeros((n_line, max(fit, 0)))
        if fit == 1:
            e[:, 0] = 1.0
    w = fade_out(m)
    lo = n - m - fit

    def fwd(x: np.ndarray) -> np.ndarray:
        line = e @ x[lo:n - m] if fit >= 1 else np.zeros(n_line)
        out = np.concatenate([x, line[m:]])
        out[n - m:n] = line[:m] + w * (x[n - m:] - line[:m])
        return out

    def adj(y: np.ndarray) -> np.ndarray:
        out = y[:n].copy()
        out[n - m:] = w * y[n - m:n]
        g_line = np.concatenate([(1.0 - w) * y[n - m:n], y[n:]])
        if fit >= 1:
            out[lo:n - m] += e.T @ g_line
        return out

    return LinearMap(n, n + int(advance), fwd, adj, "trend")


def odd_start_map(n: int, m: int) -> LinearMap:
    """``x -> [-x[m-1], ..., -x[0], x[0], ..., x[n-1]]``: ``m`` samples of the odd extension before the trial.

    Parameters
    ----------
    n : int
        Samples of the trial.
    m : int
        Samples of the extension (at most ``n``).
    """

    def fwd(x: np.ndarray) -> np.ndarray:
        return np.concatenate([-x[:m][::-1], x])

    def adj(y: np.ndarray) -> np.ndarray:
        out = np.array(y[m:], dtype=float)
        out[:m] -= y[:m][::-1]
        return out

    return LinearMap(n, n + m, fwd, adj, "odd start")


def _method_map(method: Any, n: int) -> LinearMap:
    """The method's learning filter on a trial of ``n`` samples, the source flying without learning:
    ``L1`` of closed-form filters, else the method's own ``trial_map(n)`` (a robust-set design's,
    :meth:`~..methods.robust_set.RobustSetDesign.trial_map`)."""
    if isinstance(method, LearningFilters):
        return zpk_map(method.L1, n)
    trial_map = getattr(method, "trial_map", None)
    if callable(trial_map):
        return trial_map(n)
    raise SpecError(f"finite-horizon map: method filter {type(method).__name__} is not supported; give a closed-form "
                    "(LearningFilters) or robust-set (RobustSetDesign) design")


def law_map(method: Any, n: int) -> LinearMap:
    """A method's bare filter ``e'_{j-1} -> d_f,j`` over a trial of ``n`` samples as a linear map.

    The closed form's ``L1`` or a robust-set design's law (its ``trial_map``), no band, no airframe
    correction; a design's whole law is :meth:`PairDesign.learning_law(...).error_map(n)
    <ilcdob.design.law.LearningLaw.error_map>`.

    Parameters
    ----------
    method : LearningFilters or RobustSetDesign
        The method's filter.
    n : int
        Samples of the trial.

    Returns
    -------
    LinearMap

    Raises
    ------
    SpecError
        ``n < 2`` or another kind of filter.
    """
    n = int(n)
    if n < 2:
        raise SpecError(f"`n`: got {n}, expected a trial of at least 2 samples")
    return _method_map(method, n)


def error_maps(law: LinearMap, source: LoopSystem, target: LoopSystem) -> tuple[LinearMap, LinearMap]:
    """``(A, B)``: ``e_j = A d`` and ``e'_j = B d`` for the disturbance ``d`` of one trial (module docstring).

    Parameters
    ----------
    law : LinearMap
        :func:`law_map` of the pair.
    source, target : LoopSystem
        The *true* loops of vehicles j-1 and j (true plants; models' C, Q, M).
    """
    n = law.n_in
    gd_s = causal_map(source.G_d, n, "Gd_{j-1}")
    gd_t = causal_map(target.G_d, n, "Gd_j")
    gf_t = causal_map(target.G_f, n, "Gf_j")
    b = -gd_t
    a = b + gf_t @ law @ gd_s
    return a, b


def invisible_disturbances(target: LoopSystem, n: int, tol: float = 1e-9) -> tuple[np.ndarray, list[str]]:
    """Orthonormal basis of the disturbances vehicle j's error cannot show within the trial (module docstring).

    The last ``r`` samples (``r``: leading zero Markov parameters of ``Gd_j``) and, for each zero
    ``z`` of ``Gd_j`` outside the unit circle, ``d[k] = z^(k - (n - 1 - r))`` for ``k <= n - 1 - r``;
    a direction is kept only if ``||Gd_j v|| <= tol ||Gd_j||`` on the trial.

    Parameters
    ----------
    target : LoopSystem
        Vehicle j's true loop.
    n : int
        Samples.
    tol : float
        Relative size below which ``Gd_j v`` counts as invisible.

    Returns
    -------
    basis : numpy.ndarray
        ``n x k`` orthonormal columns.
    what : list of str
        One description per direction.
    """
    h = markov_parameters(target.G_d, n)
    peak = float(np.max(np.abs(h)))
    r = int(np.argmax(np.abs(h) > 1e-12 * peak))
    vecs, what = [], []
    for i in range(min(r, n)):
        v = np.zeros(n)
        v[n - 1 - i] = 1.0
        vecs.append(v)
        what.append(f"sample {n - 1 - i} (relative degree {r})")
    gain = float(np.sum(np.abs(h)))  # an upper bound on ||Gd_j|| (l1 norm of the impulse response)
    zs = np.asarray(target.G_d.zeros(), complex)
    zs = zs[np.isfinite(zs) & (np.abs(zs) > 1 + 1e-6)]
    gd = causal_map(h, n)
    last = n - 1 - r
    for z in zs[np.imag(zs) >= -1e-12]:
        k = np.arange(last + 1)
        v = np.zeros(n, complex)
        v[:last + 1] = z ** (k - last).astype(float)
        parts = [v.real] if abs(z.imag) < 1e-12 else [v.real, v.imag]
        for p in parts:
            p = p / np.linalg.norm(p)
            if np.linalg.norm(gd(p)) <= tol * gain:
                vecs.append(p)
                what.append(f"growing like z^k into the trial's end, z = {z:.4g} (zero of Gd outside the unit circle)")
    if not vecs:
        return np.zeros((n, 0)), []
    q, _ = np.linalg.qr(np.column_stack(vecs))
    return q, what


@dataclass(frozen=True)
class FiniteHorizonRatio:
    """The whole-trial figure ``rho_N = max ||e_j|| / ||e'_j||`` over ``N`` samples (module docstring).

    Attributes
    ----------
    n : int
        Samples of the trial.
    ts : float
        Sample time, s.
    ratio : float
        ``rho_N``: the largest ``||e_j|| / ||e'_j||`` over the admissible disturbances.
    excluded : list of str
        The invisible disturbance directions left out (:func:`invisible_disturbances`).
    where_s : float
        Centre (energy-weighted time) of the worst disturbance, s; near 0 or ``N ts`` when an
        end of the trial decides the figure.
    end_share : float
        Share of the worst disturbance's energy within ``end_window_s`` of either end.
    end_window_s : float
        The window of ``end_share``, s.
    disturbance : numpy.ndarray
        The worst disturbance (unit norm).
    converged : bool
        Whether the Lanczos iteration converged (otherwise ``ratio`` is a lower bound).
    """

    n: int
    ts: float
    ratio: float
    excluded: list[str]
    where_s: float
    end_share: float
    end_window_s: float
    disturbance: np.ndarray = field(repr=False)
    converged: bool = True

    def to_dict(self) -> dict[str, Any]:
        """JSON fields (no arrays)."""
        return {"samples": self.n, "duration_s": self.n * self.ts, "ratio": self.ratio,
                "worst_disturbance_centre_s": self.where_s,
                "worst_disturbance_share_near_ends": self.end_share, "near_ends_window_s": self.end_window_s,
                "excluded_directions": list(self.excluded), "converged": self.converged}


def finite_horizon_ratio(law: LinearMap, source: LoopSystem, target: LoopSystem, *, tol: float = 1e-8,
                         end_window_s: float = 3.0, seed: int = 0) -> FiniteHorizonRatio:
    """``rho_N``: the largest whole-trial ratio ``||e_j|| / ||e'_j||`` of ``law`` over every disturbance.

    Parameters
    ----------
    law : LinearMap
        :func:`law_map` of the pair, over the trial's ``N`` samples.
    source, target : LoopSystem
        True loops of vehicles j-1 and j (``fleet.loop(name)`` for exact models).
    tol : float
        Relative tolerance of the Lanczos iteration (and, / 100, of its inner solves).
    end_window_s : float
        Window at each end of the trial for :attr:`FiniteHorizonRatio.end_share`, s.
    seed : int
        Seed of the starting vector.

    Returns
    -------
    FiniteHorizonRatio
    """
    n = law.n_in
    a, b = error_maps(law, source, target)
    z, what = invisible_disturbances(target, n)

    def proj(x: np.ndarray) -> np.ndarray:
        return x - z @ (z.T @ x) if z.shape[1] else x

    inv = zpk_map(inverse_gd_filter(target, model=False), n)  # ~ B^{-1} away from the ends

    def g1(x: np.ndarray) -> np.ndarray:
        px = proj(x)
        return proj(a.T(a(px)))

    def g2(x: np.ndarray) -> np.ndarray:
        px = proj(x)
        return proj(b.T(b(px))) + (x - px)

    def precond(x: np.ndarray) -> np.ndarray:
        px = proj(x)
        return proj(inv(inv.T(px))) + (x - px)

    op2 = LinearOperator((n, n), matvec=g2, dtype=float)
    pre = LinearOperator((n, n), matvec=precond, dtype=float)

    def solve(y: np.ndarray) -> np.ndarray:
        try:
            x, info = cg(op2, y, rtol=tol * 1e-2, atol=0.0, maxiter=20 * n, M=pre)
        except TypeError:  # scipy < 1.12 names the relative tolerance `tol`
            x, info = cg(op2, y, tol=tol * 1e-2, atol=0.0, maxiter=20 * n, M=pre)
        if info > 0:
            raise NumericalError(f"finite-horizon ratio: the conjugate-gradient solve with B^T B did not converge in "
                                 f"{info} iterations (trial of {n} samples)")
        return x

    op1 = LinearOperator((n, n), matvec=g1, dtype=float)
    minv = LinearOperator((n, n), matvec=solve, dtype=float)
    v0 = proj(np.random.default_rng(seed).normal(size=n))
    converged = True
    try:
        vals, vecs = eigsh(op1, k=1, M=op2, Minv=minv, which="LA", v0=v0, tol=tol, maxiter=max(300, n // 2))
        lam, v = float(vals[0]), vecs[:, 0]
    except ArpackNoConvergence as exc:  # keep the best Ritz value (a lower bound)
        if not len(exc.eigenvalues):
            raise NumericalError(f"finite-horizon ratio: Lanczos found no eigenvalue ({exc})") from exc
        warnings.warn(f"finite-horizon ratio: Lanczos did not converge ({exc}); the ratio is a lower bound",
                      RuntimeWarning, stacklevel=2)
        lam, v, converged = float(np.max(exc.eigenvalues)), exc.eigenvectors[:, int(np.argmax(exc.eigenvalues))], False
    d = proj(v)
    d = d / np.linalg.norm(d)
    ratio = float(np.linalg.norm(a(d)) / np.linalg.norm(b(d)))
    if not math.isfinite(ratio):
        raise NumericalError(f"finite-horizon ratio: not finite ({ratio}); Rayleigh value {lam}")
    t = np.arange(n) * target.ts
    e2 = d ** 2
    k = int(round(end_window_s / target.ts))
    share = float((np.sum(e2[:k]) + np.sum(e2[max(k, n - k):])) / np.sum(e2))
    return FiniteHorizonRatio(n, target.ts, ratio, what, float(np.sum(t * e2) / np.sum(e2)), share, end_window_s,
                              d, converged)


class PairTrials:
    """Whole trials of one pair with the same disturbance, flown through the loops' lifted maps.

    For linear loops from rest this is what :func:`~ilcdob.validation.simulate.simulate_flight`
    computes sample by sample (to rounding), in ``O(N log N)``: the source flies without learning,
    its error goes through a learning function to the target, which flies with and without it.

    Parameters
    ----------
    source, target : LoopSystem
        True loops of vehicles j-1 and j.
    n : int
        Samples of every trial.
    """

    def __init__(self, source: LoopSystem, target: LoopSystem, n: int):
        self.n = int(n)
        self.gd_s = causal_map(source.G_d, self.n)
        self.gd_t = causal_map(target.G_d, self.n)
        self.gf_t = causal_map(target.G_f, self.n)

    def with_source(self, source: LoopSystem) -> "PairTrials":
        """The same target's trials with another source loop (the target's maps are shared, not recomputed).

        Parameters
        ----------
        source : LoopSystem
            True loop of vehicle j-1.
        """
        out = copy.copy(self)
        out.gd_s = causal_map(source.G_d, self.n)
        return out

    def errors(self, learn: Callable[[np.ndarray], np.ndarray], d: object) -> tuple[np.ndarray, np.ndarray]:
        """``(e_j, e'_j)`` of one trial of disturbance ``d`` (hover at 0), m.

        Parameters
        ----------
        learn : callable
            ``e'_{j-1} -> d_f,j`` (e.g. ``lambda e: design.learning(e, 0 * e).d_f``).
        d : array, m/s^2
            Disturbance of both vehicles, ``n`` samples.
        """
        d = as_signal(d, "d", self.n)
        e_prev = -self.gd_s(d)
        e0 = -self.gd_t(d)
        return e0 - self.gf_t(np.asarray(learn(e_prev), float)), e0

    def ratio(self, learn: Callable[[np.ndarray], np.ndarray], d: object) -> float:
        """``||e_j|| / ||e'_j||`` of one trial (:meth:`errors`).

        Parameters
        ----------
        learn : callable
            ``e'_{j-1} -> d_f,j``.
        d : array, m/s^2
            Disturbance of both vehicles.
        """
        e, e0 = self.errors(learn, d)
        return float(np.linalg.norm(e) / np.linalg.norm(e0))
