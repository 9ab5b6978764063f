"""Robust norm-optimal learning over the Delta set, as an SOCP (docs/theory.md sections 3 and 5).

For system j with K plausible true plants (samples of the Delta set, :func:`~ilcdob.design.delta_set`),
``e0_k`` is the error system j would fly under sample k without learning and
``e_k = e0_k - Gf_k d_f`` the error with the learning signal ``d_f``. The design is::

    minimise    t + lam ||d_f||^2 + mu ||Diff d_f||^2
    subject to  ||W e_k||^2 <= t                  for every k   (epigraph of the worst case)
                ||e_k||     <= rho ||e0_k||       for every k   (guaranteed improvement)

The epigraph is taken of the *squares* ``||W e_k||^2`` (cvxpy turns each into one rotated
second-order cone), so for K = 1 with an inactive improvement constraint the problem is
exactly the regularised least-squares (norm-optimal ILC) problem
``(G^T W^2 G + lam I + mu Diff^T Diff) d_f = G^T W^2 e0``.

Scale (docs/theory.md section 5): the predicted errors are not formed with dense N x N lifted
matrices. Each ``Gf_k`` enters through its state-space equations as sparse equality
constraints ``x_{t+1} = A x_t + B d_t``, ``x_0 = 0``, ``y_t = C x_t + D d_t``, in a balanced
truncation (:func:`~ilcdob.design.filters.reduction.reduced_realisation`, SLICOT AB09AD in discrete
time), so the states are well scaled and few (6-7 of 11-12 at the default ``reduction_tol``).
The truncation's error bound ``eps_k`` (``>= ||Gf_k - Gf_k,r||_inf``) is carried into the
improvement constraint, ``||e_k,r|| + eps_k ||d_f|| <= rho ||e0_k||``, so the guarantee holds
for the full models; every reported ratio is recomputed by simulating the full models. The
signals are normalised inside: ``e0`` by ``s = max_k ||e0_k||`` and ``d_f`` by ``s / g`` with
``g`` the peak gain of the first model's ``Gf``; the weights are rescaled so the optimum is
unchanged.

The cvxpy problem is built once with Parameters (the normalised ``e0`` and the right-hand
sides ``rho ||e0_k||``) and checked to be DPP. By default (``backend="direct"``) the same conic
program is handed to Clarabel as data assembled once with scipy.sparse, only ``b`` changing per
trial -- what cvxpy's DPP path does, without its compilation, whose memory grows as
parameters x variables (> 24 GB at K = 5, N = 1000; cvxpy issues #886, #1622).

Vehicles on their own controller (:class:`~ilcdob.channel_loop.ChannelLoop`, docs/closed_loop.md): their
samples are drawn channel maps (:func:`~ilcdob.design.sets.delta.channel_delta_set`), ``d_f`` is the
learning signal on the target's channel and ``Gf_k`` its channel map. Under hypothesis ``k`` the source's
reconstructed disturbance, mapped through the target's ``Gd_k``, is ``e0_k = Gf_{j,k}{u_k}`` with ``u_k``
the Theorem's signal for that pair of maps (``L1_k e + L2_k u_{j-1}``,
:func:`~ilcdob.design.maps.channel_filters.channel_filters`): ``Gd_j Gd_{j-1}^{-1} = Gf_j L1``, which
also cancels the add-on DOBs' ``1 - Q`` zero at ``z = 1`` as the closed form does.

Infeasible ``rho``: the smallest feasible ``rho`` is found by bisection, each step certified by
the simulated ratios, and reported with the binding models. Near that edge Clarabel may stop
with ``InsufficientProgress``; the bisection then tells infeasibility from solver trouble.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import clarabel
import control as ct
import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ilcdob.channel_loop import ChannelLoop
from ilcdob.errors import IlcdobError, SignalError, SpecError
from ilcdob.loop import LoopSystem, freqresp

from ..maps.channel_filters import channel_filters
from ..maps.closed_form import reconstruct_disturbance, simulate_map
from ..filters.reduction import reduced_realisation

__all__ = ["RobustOptions", "RobustDesign", "RobustDesigner", "RobustPairDesigner", "RobustInfeasibleError",
           "RobustSolverError", "predicted_errors"]

_OK = ("optimal", "optimal_inaccurate")
_DIRECT_METHOD = "faer"  # supernodal, multithreaded; faster than qdldl on these KKT systems
#: Threads of Clarabel's KKT solver (0: its own choice, every core); campaigns set 1 on their workers, which
#: share the cores with each other.
CLARABEL_THREADS = 0
_INFEASIBLE = ("infeasible", "infeasible_inaccurate")
#: Clarabel's static KKT regularisation, tried in turn while the solve ends in :data:`_RETRY` (``_run_direct``).
_STATIC_REGULARIZATION = (1e-10, 1e-8)
_RETRY = ("NumericalError",)
_CLARABEL_STATUS = {"Solved": "optimal", "AlmostSolved": "optimal_inaccurate",
                    "PrimalInfeasible": "infeasible", "AlmostPrimalInfeasible": "infeasible_inaccurate",
                    "DualInfeasible": "unbounded", "AlmostDualInfeasible": "unbounded_inaccurate"}


class RobustInfeasibleError(IlcdobError, ValueError):
    """No learning signal meets ``||e_k|| <= rho ||e0_k||`` for every model.

    Parameters
    ----------
    message : str
        The error message (states the smallest feasible rho and the next step).
    rho, rho_feasible, binding
        Stored as the attributes below.

    Attributes
    ----------
    rho : float
        The requested improvement factor.
    rho_feasible : float
        Smallest feasible factor found by bisection (within ``bisection_tol``).
    binding : tuple of int
        Indices of the models whose improvement constraint binds at ``rho_feasible``.
    """

    def __init__(self, message: str, rho: float, rho_feasible: float, binding: tuple[int, ...]):
        super().__init__(message)
        self.rho = rho
        self.rho_feasible = rho_feasible
        self.binding = binding


class RobustSolverError(IlcdobError, RuntimeError):
    """The conic solver failed (neither a solution nor a certificate of infeasibility)."""


@dataclass(frozen=True)
class RobustOptions:
    """Options of the robust design (docs/theory.md section 3).

    Attributes
    ----------
    rho : float
        Guaranteed improvement factor, ``||e_k|| <= rho ||e0_k||``; in (0, inf), < 1 to
        guarantee improvement on every model (1 or more makes the constraint harmless).
    lam : float
        Weight of ``||d_f||^2`` (s^4, i.e. m^2 per (m/s^2)^2), >= 0.
    mu : float
        Weight of ``||Diff d_f||^2`` (first differences), >= 0.
    weight : float or sequence of float
        ``W``: a scalar or N per-sample weights (>= 0, not all zero) on the error.
    solver : str
        cvxpy solver name (``"CLARABEL"``; ``"SCS"`` as a fallback).
    verbose : bool
        Print the solver log.
    bisection_tol : float
        Absolute tolerance on rho of the infeasibility bisection, in (0, 0.1].
    backend : str
        ``"direct"`` (default, needs ``solver="CLARABEL"``): the same SOCP as conic data
        assembled once with scipy.sparse and handed to Clarabel, only ``b`` changing per trial;
        ``"cvxpy"``: solve the DPP cvxpy problem (any cvxpy solver). cvxpy's one-time DPP
        compilation grows about quadratically with size (3.7 s at K=5, N=300; 16 s at N=600),
        so use it for small problems or other solvers only.
    reduction_tol : float
        Balanced truncation of each ``Gf_k``: states with Hankel singular value below
        ``reduction_tol`` times the largest are dropped
        (:func:`~ilcdob.design.filters.reduction.reduced_realisation`). The truncation error bound
        ``eps_k`` is added to the improvement constraint, which stays a guarantee for the full
        model. In [0, 0.1); default 1e-5 (6-7 of 11-12 states).
    """

    rho: float = 0.95
    lam: float = 1e-8
    mu: float = 1e-6
    weight: float | Sequence[float] = 1.0
    solver: str = "CLARABEL"
    verbose: bool = False
    bisection_tol: float = 1e-3
    backend: str = "direct"
    reduction_tol: float = 1e-5

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rho) and self.rho > 0):
            raise SpecError(f"`rho`: got {self.rho!r}, expected a finite improvement factor > 0 (e.g. 0.95)")
        for name in ("lam", "mu"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise SpecError(f"`{name}`: got {v!r}, expected a finite weight >= 0")
        w = np.asarray(self.weight, dtype=float)
        if w.ndim > 1 or not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
            raise SpecError(f"`weight`: got {self.weight!r}, expected a scalar or 1-D sequence of finite "
                            "weights >= 0, not all zero")
        if not isinstance(self.solver, str) or self.solver.upper() not in cp.installed_solvers():
            raise SpecError(f"`solver`: got {self.solver!r}, expected one of the installed cvxpy solvers "
                            f"{cp.installed_solvers()}")
        if self.backend not in ("direct", "cvxpy"):
            raise SpecError(f"`backend`: got {self.backend!r}, expected 'direct' or 'cvxpy'")
        if self.backend == "direct" and str(self.solver).upper() != "CLARABEL":
            raise SpecError(f"`solver`: got {self.solver!r} with backend='direct', which calls Clarabel itself; "
                            "use backend='cvxpy' for other solvers")
        if not (np.isfinite(self.reduction_tol) and 0 <= self.reduction_tol < 0.1):
            raise SpecError(f"`reduction_tol`: got {self.reduction_tol!r}, expected a relative Hankel singular "
                            "value in [0, 0.1) (0 keeps every state of the minimal realisation)")
        if not (0 < self.bisection_tol <= 0.1):
            raise SpecError(f"`bisection_tol`: got {self.bisection_tol!r}, expected a value in (0, 0.1]")


@dataclass(frozen=True)
class RobustDesign:
    """Result of one robust design.

    Attributes
    ----------
    d_f : numpy.ndarray
        Learning signal, m/s^2 (N,).
    rho : float
        The improvement factor imposed.
    ratios : numpy.ndarray
        ``||e_k|| / ||e0_k||`` per model (K,), recomputed from the solution.
    worst_ratio : float
        ``max(ratios)``.
    objective : float
        ``max_k ||W e_k||^2 + lam ||d_f||^2 + mu ||Diff d_f||^2`` in the original units
        (recomputed from the solution).
    status : str
        cvxpy status (``"optimal"`` or ``"optimal_inaccurate"``).
    solve_time : float
        Wall-clock time of the solve call, s (parameter mapping + solver).
    iterations : int or None
        Solver iterations.
    errors : numpy.ndarray
        Predicted errors with learning ``e_k`` (K, N), m.
    """

    d_f: np.ndarray
    rho: float
    ratios: np.ndarray
    worst_ratio: float
    objective: float
    status: str
    solve_time: float
    iterations: int | None
    errors: np.ndarray = field(repr=False)


def predicted_errors(d_rec: object, loops: Sequence[LoopSystem]) -> np.ndarray:
    """Errors without learning ``e0_k = -Gd_k{d_rec}`` under every model (K, N), m.

    Parameters
    ----------
    d_rec : array, m/s^2
        Reconstructed disturbance, e.g. ``reconstruct_disturbance(prev_loop, e_prev, df_prev)``.
    loops : sequence of LoopSystem
        System j under each model (``DeltaSet.loops``).
    """
    d = np.asarray(d_rec, dtype=float)
    if d.ndim != 1 or d.size < 2 or not np.all(np.isfinite(d)):
        raise SignalError(f"`d_rec`: got shape {d.shape}, expected a finite 1-D signal of >= 2 samples")
    if len(loops) < 1:
        raise SpecError("`loops`: got no loops, expected one LoopSystem per model (DeltaSet.loops)")
    return np.array([-simulate_map(lp.G_d, d) for lp in loops])


def _state_space_blocks(sys: ct.StateSpace, n: int, gain: float):
    """Sparse matrices of ``y = sys{d}`` from rest: ``lhs x = inp d``, ``y = out x + dd d``.

    ``x`` stacks ``x_1 .. x_{n-1}`` (``x_0 = 0``); ``gain`` scales the output.
    """
    a, b = np.asarray(sys.A, float), np.asarray(sys.B, float)
    c, dd = np.asarray(sys.C, float) * gain, float(np.asarray(sys.D).ravel()[0]) * gain
    nx, m = a.shape[0], n - 1
    shift = sp.diags(np.ones(m - 1), -1, shape=(m, m), format="csr")
    lhs = sp.eye(m * nx, format="csr") - sp.kron(shift, sp.csr_matrix(a), format="csr")
    inp = sp.kron(sp.hstack([sp.eye(m), sp.csr_matrix((m, 1))]), sp.csr_matrix(b), format="csr")
    out = sp.vstack([sp.csr_matrix((1, m * nx)), sp.kron(sp.eye(m), sp.csr_matrix(c))], format="csr")
    return lhs, inp, out, dd * sp.eye(n, format="csr")


class RobustDesigner:
    """Robust norm-optimal design for one system over K models, built once (see module docstring).

    Parameters
    ----------
    loops : sequence of LoopSystem
        System j under each model (``DeltaSet.loops``); their ``G_f`` define the constraints.
    n : int
        Trial length in samples (>= 3).
    options : RobustOptions, optional

    Raises
    ------
    SpecError
        Bad ``n``, no loops, loops with different sample times, or weights of the wrong length.
    RobustSolverError
        The problem is not DPP (a bug: report it).
    """

    def __init__(self, loops: Sequence[LoopSystem], n: int, options: RobustOptions | None = None):
        self.options = options if options is not None else RobustOptions()
        self.loops = tuple(loops)
        if not self.loops:
            raise SpecError("`loops`: got no loops, expected one LoopSystem per model (DeltaSet.loops)")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
            raise SpecError(f"`n`: got {n!r}, expected a trial length >= 3 samples")
        ts = {round(lp.ts, 12) for lp in self.loops}
        if len(ts) != 1:
            raise SpecError(f"`loops`: sample times {sorted(ts)} differ; all models must share one")
        self.n = int(n)
        w = np.asarray(self.options.weight, dtype=float)
        if w.ndim == 1 and w.size != self.n:
            raise SpecError(f"`weight`: got {w.size} weights, expected a scalar or n = {self.n} weights")
        self._w = np.broadcast_to(w, (self.n,)).copy()
        k = len(self.loops)
        reduced = [reduced_realisation(lp.G_f, self.options.reduction_tol) for lp in self.loops]
        self.realisations = tuple(r for r, _ in reduced)
        self.truncation_bounds = np.array([b for _, b in reduced])
        # input scaling: peak gain of the first model's Gf on a grid up to Nyquist
        lp0 = self.loops[0]
        grid = np.logspace(-3, np.log10(0.999 * np.pi / lp0.ts), 400)
        self._gain = float(np.max(np.abs(freqresp(lp0.G_f, grid))))
        if not (np.isfinite(self._gain) and self._gain > 0):
            raise SpecError(f"`loops`: system {lp0.name!r} has a zero or non-finite G_f gain ({self._gain})")

        # one block-sparse system for all models; identical loops (same object) share their states
        unique: dict[int, int] = {}
        for lp in self.loops:
            unique.setdefault(id(lp), len(unique))
        self._slot = [unique[id(lp)] for lp in self.loops]
        reals = {unique[id(lp)]: real for lp, real in zip(self.loops, self.realisations)}
        blocks = [_state_space_blocks(reals[u], self.n, 1.0 / self._gain) for u in range(len(unique))]
        lhs = sp.block_diag([b[0] for b in blocks], format="csr")
        inp = sp.vstack([b[1] for b in blocks], format="csr")
        out = sp.block_diag([b[2] for b in blocks], format="csr")
        feed = sp.vstack([b[3] for b in blocks], format="csr")
        pick = sp.kron(sp.csr_matrix((np.ones(k), (np.arange(k), self._slot)), shape=(k, len(unique))),
                       sp.eye(self.n), format="csr")  # model k -> its unique map's outputs
        self._e0 = cp.Parameter(k * self.n, name="e0")
        self._rhs = cp.Parameter(k, nonneg=True, name="rho_norm_e0")
        self._d = cp.Variable(self.n, name="d_f")
        self._t = cp.Variable(name="t")
        self._x = cp.Variable(lhs.shape[0], name="x")
        self._e = cp.Variable(k * self.n, name="e")
        cons: list = [lhs @ self._x == inp @ self._d,
                      self._e == self._e0 - pick @ (out @ self._x + feed @ self._d)]
        self._errors = [self._e[i * self.n:(i + 1) * self.n] for i in range(k)]
        cons += [cp.sum_squares(cp.multiply(self._w, e)) <= self._t for e in self._errors]
        eps = self.truncation_bounds / self._gain  # l2-gain bound of the truncation, normalised units
        self._improve = [cp.norm(e, 2) + eps[i] * cp.norm(self._d, 2) <= self._rhs[i]
                         for i, e in enumerate(self._errors)]
        cons += self._improve
        self._conic = self._conic_data(lhs, inp, out, feed, pick, k) if self.options.backend == "direct" else None
        self._lam_s = cp.Parameter(nonneg=True, name="lam")
        self._mu_s = cp.Parameter(nonneg=True, name="mu")
        obj = self._t + self._lam_s * cp.sum_squares(self._d) + self._mu_s * cp.sum_squares(cp.diff(self._d))
        self.problem = cp.Problem(cp.Minimize(obj), cons)
        if not self.problem.is_dpp():
            raise RobustSolverError("robust design: the cvxpy problem is not DPP, so it would be recompiled at "
                                    "every solve; this is a bug in ilcdob.design.methods.robust, please report it")
        # normalised d = d_f * gain / s: lam and mu scale by 1/gain^2 (s cancels)
        self._lam_s.value = self.options.lam / self._gain**2
        self._mu_s.value = self.options.mu / self._gain**2

    # ------------------------------------------------------------------ internals
    def _conic_data(self, lhs, inp, out, feed, pick, k: int) -> dict:
        """Clarabel form ``min 1/2 z'Pz + q'z, A z + s = b, s in cones``, z = [d, x, t, u, v].

        The errors are not variables: ``e_i = e0_i - M_i z`` with ``M_i z`` model i's output, so
        ``e0`` enters ``b`` only. ``u_i >= ||e_i||``, ``v >= ||d||`` and ``u_i + eps_i v <= rho ||e0_i||``
        (the improvement constraint with the truncation error bound ``eps_i``); ``||W e_i||^2 <= t``.
        """
        n, nx = self.n, lhs.shape[0]
        zt = n + nx
        nz = zt + 1 + k + 1
        zu, zv = zt + 1, nz - 1
        lam, mu = self.options.lam / self._gain**2, self.options.mu / self._gain**2
        diff = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n))
        pd = 2.0 * (lam * sp.eye(n) + mu * (diff.T @ diff))
        P = sp.block_diag([sp.triu(pd), sp.csc_matrix((nz - n, nz - n))], format="csc")
        q = np.zeros(nz)
        q[zt] = 1.0
        zx = sp.csr_matrix

        def unit(rows: list[int], cols: list[int], vals: list[float]) -> sp.csr_matrix:
            return sp.csr_matrix((vals, (rows, cols)), shape=(max(rows) + 1, nz))

        outputs = sp.hstack([pick @ feed, pick @ out, zx((k * n, nz - n - nx))], format="csr")  # rows M_i
        rows = [sp.hstack([-inp, lhs, zx((nx, nz - n - nx))])]
        b: list = [np.zeros(nx)]
        cones = [clarabel.ZeroConeT(nx)]
        eps = self.truncation_bounds / self._gain
        rows.append(sp.hstack([zx((k, zu)), sp.eye(k), sp.csr_matrix(eps[:, None])]))  # u + eps v <= r
        b.append(("rhs",))
        cones.append(clarabel.NonnegativeConeT(k))
        wdiag = sp.diags(2.0 * self._w)
        for i in range(k):  # ||W e_i||^2 <= t  <=>  ||(t - 1, 2 W e_i)|| <= t + 1
            rows.append(sp.vstack([unit([0, 1], [zt, zt], [-1.0, -1.0]), wdiag @ outputs[i * n:(i + 1) * n]]))
            b.append(("epigraph", i))
            cones.append(clarabel.SecondOrderConeT(n + 2))
        for i in range(k):  # ||e_i|| <= u_i
            rows.append(sp.vstack([unit([0], [zu + i], [-1.0]), outputs[i * n:(i + 1) * n]]))
            b.append(("improvement", i))
            cones.append(clarabel.SecondOrderConeT(n + 1))
        rows.append(sp.vstack([unit([0], [zv], [-1.0]), sp.hstack([-sp.eye(n), zx((n, nz - n))])]))  # ||d|| <= v
        b.append(np.zeros(n + 1))
        cones.append(clarabel.SecondOrderConeT(n + 1))
        A = sp.vstack(rows, format="csc")
        return {"P": P, "q": q, "A": A, "b": b, "cones": cones}

    def _run_direct(self, rho: float):
        c = self._conic
        e0 = self._e0_raw / self._scale
        w2 = 2.0 * self._w

        def fill(part):
            if not isinstance(part, tuple):
                return part
            if part[0] == "rhs":
                return rho * self._norms_s
            i = part[1]
            if part[0] == "epigraph":
                return np.concatenate([[1.0, -1.0], w2 * e0[i]])
            return np.concatenate([[0.0], e0[i]])

        b = np.concatenate([fill(part) for part in c["b"]])
        t0 = time.perf_counter()
        # smaller static regularisation than Clarabel's 1e-8 first: with near-perfect learning the optimum is ~1e-6
        # and the default lets the primal residual of the state equations creep up (AlmostSolved at K=20, N=1000);
        # where that small one leaves the KKT factorisation in numerical trouble (relative degree 4 at 2 ms: a
        # NumericalError after 8 iterations), Clarabel's default solves it (16 iterations)
        for reg in _STATIC_REGULARIZATION:
            status, sol = self._clarabel(b, reg, rho)
            if status not in _RETRY:
                break
        self._z = np.asarray(sol.x, dtype=float)
        self._iters = int(sol.iterations)
        return status, time.perf_counter() - t0

    def _clarabel(self, b: np.ndarray, regularization: float, rho: float) -> tuple[str, Any]:
        """One Clarabel solve of the conic data with right-hand side ``b``: its status (cvxpy's names) and solution."""
        c = self._conic
        settings = clarabel.DefaultSettings()
        settings.verbose = bool(self.options.verbose)
        settings.direct_solve_method = _DIRECT_METHOD
        settings.max_threads = CLARABEL_THREADS
        settings.static_regularization_constant = regularization
        try:  # a fresh solver per trial: updating b in a persistent one reuses the first trial's equilibration,
            # which made designs depend on solve history (~20 % faster; campaigns must reproduce samples exactly)
            sol = clarabel.DefaultSolver(c["P"], c["q"], c["A"], b, c["cones"], settings).solve()
        except Exception as exc:  # Clarabel raises on malformed data or internal failures
            raise RobustSolverError(
                f"robust design: Clarabel failed at rho = {rho:g} ({exc}). Next steps: try backend='cvxpy', "
                "solver='SCS', scale the signals (e0 in m, d_f in m/s^2), raise lam/mu, or verbose=True") from exc
        return _CLARABEL_STATUS.get(str(sol.status), str(sol.status)), sol

    def _check_e0(self, e0: object) -> np.ndarray:
        e0 = np.asarray(e0, dtype=float)
        k = len(self.loops)
        if e0.ndim == 1 and k == 1:
            e0 = e0[None, :]
        if e0.shape != (k, self.n) or not np.all(np.isfinite(e0)):
            raise SignalError(f"`e0`: got shape {e0.shape}, expected finite predicted errors of shape "
                              f"(K, N) = ({k}, {self.n}); build them with predicted_errors(d_rec, loops)")
        norms = np.linalg.norm(e0, axis=1)
        if np.any(norms == 0):
            raise SignalError(f"`e0`: models {np.flatnonzero(norms == 0).tolist()} predict zero error; there is "
                              "nothing to improve under them (drop them or use a longer/disturbed trial)")
        return e0

    def _run(self, rho: float):
        if self._conic is not None:
            return self._run_direct(rho)
        self._rhs.value = rho * self._norms_s
        kwargs = {"solver": self.options.solver, "verbose": self.options.verbose}
        t0 = time.perf_counter()
        try:
            self.problem.solve(**kwargs)
        except cp.error.SolverError as exc:
            raise RobustSolverError(
                f"robust design: solver {self.options.solver!r} failed at rho = {rho:g} ({exc}). Next steps: try "
                "solver='SCS', scale the signals (e0 in m, d_f in m/s^2), raise lam/mu, or pass verbose=True "
                "to see the solver log") from exc
        return self.problem.status, time.perf_counter() - t0

    def _result(self, rho: float, status: str, elapsed: float) -> RobustDesign:
        d_n = self._z[:self.n] if self._conic is not None else self._d.value
        d_f = np.asarray(d_n, dtype=float) * self._scale / self._gain
        errors = np.array([self._e0_raw[k] - simulate_map(lp.G_f, d_f) for k, lp in enumerate(self.loops)])
        ratios = np.linalg.norm(errors, axis=1) / np.linalg.norm(self._e0_raw, axis=1)
        worst = float(np.max(np.sum((self._w * errors) ** 2, axis=1)))
        obj = worst + self.options.lam * float(d_f @ d_f) + self.options.mu * float(np.sum(np.diff(d_f) ** 2))
        if self._conic is not None:
            iters = self._iters
        else:
            stats = self.problem.solver_stats
            iters = getattr(stats, "num_iters", None) if stats is not None else None
        return RobustDesign(d_f=d_f, rho=rho, ratios=ratios, worst_ratio=float(ratios.max()), objective=obj,
                            status=status, solve_time=elapsed, iterations=iters, errors=errors)

    def _feasible(self, rho: float) -> bool:
        """Solver success *and* true ratios (full models, by simulation) within rho."""
        status, elapsed = self._run(rho)
        return status in _OK and self._result(rho, status, elapsed).worst_ratio <= rho + 1e-6

    def _bisect(self, rho: float) -> tuple[float, tuple[int, ...]]:
        lo, hi = rho, max(1.0, rho)
        if not self._feasible(hi):
            raise RobustSolverError(
                f"robust design: even rho = {hi:g} (d_f = 0 is feasible) failed; the solver is in numerical "
                "trouble. Next steps: try backend='cvxpy' with solver='SCS', scale the signals, raise lam/mu, "
                "verbose=True")
        tol = self.options.bisection_tol
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            if self._feasible(mid):
                hi = mid
            else:
                lo = mid
        status, elapsed = self._run(hi)
        ratios = self._result(hi, status, elapsed).ratios
        binding = tuple(int(i) for i in np.flatnonzero(ratios >= hi - 2 * tol))
        return hi, binding

    # ------------------------------------------------------------------ public
    def solve(self, e0: object, rho: float | None = None) -> RobustDesign:
        """Design ``d_f`` for the predicted errors ``e0`` (K, N) (one SOCP solve, no recompilation).

        Parameters
        ----------
        e0 : array (K, N), m
            Errors without learning under every model (:func:`predicted_errors`).
        rho : float, optional
            Override ``options.rho`` for this solve.

        Returns
        -------
        RobustDesign

        Raises
        ------
        SignalError
            ``e0`` of the wrong shape, non-finite, or zero under some model.
        RobustInfeasibleError
            No ``d_f`` meets the improvement constraints at ``rho``; carries the smallest feasible
            rho (bisection on the same problem) and the binding models.
        RobustSolverError
            The solver failed; the message lists next steps.
        """
        rho = self.options.rho if rho is None else float(rho)
        if not (np.isfinite(rho) and rho > 0):
            raise SpecError(f"`rho`: got {rho!r}, expected a finite improvement factor > 0")
        self._e0_raw = self._check_e0(e0)
        norms = np.linalg.norm(self._e0_raw, axis=1)
        self._scale = float(norms.max())
        if self._conic is None:
            self._e0.value = (self._e0_raw / self._scale).ravel()
        self._norms_s = norms / self._scale
        status, elapsed = self._run(rho)
        if status not in _OK:  # infeasible, or solver trouble, which near the feasibility edge often means it
            rho_f, binding = self._bisect(rho)
            if rho_f > rho + self.options.bisection_tol or status in _INFEASIBLE:
                raise RobustInfeasibleError(
                    f"robust design: rho = {rho:g} is infeasible (solver status {status!r}), no learning signal "
                    f"makes ||e_k|| <= rho ||e0_k|| for all {len(self.loops)} models. Smallest feasible rho found "
                    f"by bisection: {rho_f:.4g} (tolerance {self.options.bisection_tol:g}); binding models: "
                    f"{list(binding)}. Next step: use rho >= {rho_f:.4g}, or drop/relax the binding models "
                    "(smaller Delta bound).", rho=rho, rho_feasible=rho_f, binding=binding)
            raise RobustSolverError(
                f"robust design: solver {self.options.solver!r} returned status {status!r} at rho = {rho:g}, "
                f"although rho = {rho_f:.4g} is feasible. Next steps: try a slightly larger rho, "
                "backend='cvxpy' with solver='SCS', scale the signals (e0 in m, d_f in m/s^2), raise lam/mu, "
                "or pass verbose=True to see the solver log")
        if status == "optimal_inaccurate":
            warnings.warn(f"robust design: solver {self.options.solver!r} returned 'optimal_inaccurate' at rho = "
                          f"{rho:g}; check the returned ratios, or try solver='SCS' / verbose=True",
                          RuntimeWarning, stacklevel=2)
        return self._result(rho, status, elapsed)


class RobustPairDesigner:
    """Robust learning of system j from a trial of system j-1 over paired Delta samples.

    Model ``k`` is the hypothesis "system j-1 flew with true plant ``sources[k]`` and system j
    will fly with ``targets[k]``" (both loops keep their models' C, Q and M). For a trial
    ``(e_{j-1}, d_f,{j-1})`` the disturbance is reconstructed under each hypothesis
    (:func:`~ilcdob.design.reconstruct_disturbance` with ``model=False``, the inverse of
    Theorem's ``Gd_{j-1}``), giving ``e0_k = -Gd_{j,k}{d_rec,k}``, and
    :class:`RobustDesigner` chooses ``d_f,j`` (docs/theory.md section 3). Designers are built
    once per trial length and re-solved per trial.

    Parameters
    ----------
    sources, targets : sequence of LoopSystem, or of ChannelLoop
        Equal-length lists of sampled loops of systems j-1 and j (e.g. the nominal loop first,
        then ``DeltaSet.loops``): ilcdob's loops, or vehicles on their own controller (module
        docstring; a pair mixing the two kinds is refused).
    options : RobustOptions, optional
    relax : bool
        If the requested rho is infeasible, design at the smallest feasible rho found by
        bisection (plus ``2 * bisection_tol``) with a warning instead of raising.
    """

    def __init__(self, sources: Sequence[LoopSystem], targets: Sequence[LoopSystem],
                 options: RobustOptions | None = None, relax: bool = False):
        self.sources, self.targets = tuple(sources), tuple(targets)
        if not self.sources or len(self.sources) != len(self.targets):
            raise SpecError(f"`sources`/`targets`: got {len(self.sources)} and {len(self.targets)} loops, "
                            "expected the same number (>= 1) of paired samples")
        kinds = {isinstance(lp, ChannelLoop) for lp in (*self.sources, *self.targets)}
        if len(kinds) > 1:
            raise SpecError("`sources`/`targets`: a robust pair of a vehicle on its own controller and ilcdob's PID + "
                            "DOB loop is not built (their learning signals enter different points); design it with "
                            "the closed form")
        self.channel = kinds == {True}
        self._pairs: list | None = None
        self.options = options if options is not None else RobustOptions()
        self.relax = bool(relax)
        self._designers: dict[int, RobustDesigner] = {}

    def predicted_errors(self, e_prev: object, df_prev: object) -> np.ndarray:
        """``e0_k`` (K, N), m: system j's error without learning under every hypothesis.

        Parameters
        ----------
        e_prev : array, m
            System j-1's tracking error in its trial.
        df_prev : array, m/s^2
            The learning signal system j-1 flew with (zeros if none).

        Returns
        -------
        numpy.ndarray
            ``-Gd_{j,k}{d_rec,k}`` for every hypothesis ``k`` (docs/theory.md section 3; vehicles on their own
            controller: the module docstring).
        """
        if self.channel:
            if self._pairs is None:  # the Theorem's filters under every hypothesis, built once
                self._pairs = [channel_filters(src, tgt) for src, tgt in zip(self.sources, self.targets)]
            return np.array([simulate_map(lf.target.G_f, lf.apply(e_prev, df_prev)) for lf in self._pairs])
        return np.array([-simulate_map(tgt.G_d, reconstruct_disturbance(src, e_prev, df_prev, model=False))
                         for src, tgt in zip(self.sources, self.targets)])

    def design(self, e_prev: object, df_prev: object) -> RobustDesign:
        """Robust learning signal of system j for one trial of system j-1.

        Parameters
        ----------
        e_prev : array, m
            System j-1's tracking error in its trial.
        df_prev : array, m/s^2
            The learning signal system j-1 flew with (zeros if none).

        Returns
        -------
        RobustDesign
            The design (at a relaxed rho, with a warning, when ``relax`` and rho is infeasible).

        Raises
        ------
        RobustInfeasibleError
            ``rho`` is infeasible and ``relax`` is False.
        """
        e0 = self.predicted_errors(e_prev, df_prev)
        n = e0.shape[1]
        if n not in self._designers:
            self._designers[n] = RobustDesigner(self.targets, n, self.options)
        designer = self._designers[n]
        try:
            return designer.solve(e0)
        except RobustInfeasibleError as exc:
            if not self.relax:
                raise
            rho = exc.rho_feasible + 2 * self.options.bisection_tol
            warnings.warn(f"robust design: rho = {exc.rho:g} infeasible, designed at rho = {rho:.4g} "
                          f"(binding models {list(exc.binding)})", RuntimeWarning, stacklevel=2)
            return designer.solve(e0, rho=rho)

    def learn(self, e_prev: object, df_prev: object) -> np.ndarray:
        """The learning signal only (``design(...).d_f``), m/s^2.

        Parameters
        ----------
        e_prev : array, m
            System j-1's tracking error in its trial.
        df_prev : array, m/s^2
            The learning signal system j-1 flew with (zeros if none).

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2.
        """
        return self.design(e_prev, df_prev).d_f
