"""Output-error fits of continuous-time transfer functions, solved with CasADi/IPOPT.

The criterion is the simulation error (output error, MATLAB's ``tfest`` default with
``Focus='simulation'``)::

    minimise  sum_e sum_k ( y_e[k] - yhat_e[k](theta, delay, x0_e) )^2

where ``yhat`` is the exact ZOH response of ``G(s) = B(s)/(s^K A(s)) e^{-s delay}`` from
the initial state ``x0_e`` of each experiment ``e`` (estimated, or zero). The sampled
dynamics ``Phi = e^{A ts}`` and the input matrices (modified z-transform for the fractional
part of the delay) are built symbolically with a scaled-and-squared Taylor series, the
trajectory with ``casadi.Function.mapaccum``, and IPOPT gets exact derivatives.

Initialisation (so that IPOPT does not stall in a local minimum): candidates from SRIVC
(:mod:`.srivc`) and from a grid of pole locations with the numerator solved by linear least
squares; the candidate with the lowest simulation error starts IPOPT. With ``delay="auto"``
the same grid scans the delay in half-sample steps; IPOPT then refines the fractional part.

Closed-loop data (the vehicles fly under their PID, so the commanded acceleration depends on
the measured position): the direct output-error fit used here is consistent when the
disturbance on the output is white measurement noise and the plant is strictly proper --
the noise sample v[k] reaches the input at k and the output only from k+1 on, so the
output error equals v and is uncorrelated with the regressors (Ljung, System
Identification, 2nd ed., sec. 13.4: the direct method is consistent when the noise model is
right). It is biased when the output disturbance is coloured (turbulence, unmodelled
vibration) and fed back, in proportion to that disturbance's power relative to the
excitation: fly closed-loop experiments in calm air with a strong external excitation
(reference steps, an injected chirp), and check ``input_correlation`` of the result,
which flags residuals correlated with the input.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from typing import Callable

import casadi as cs
import numpy as np

from ilcdob.errors import IlcdobError, SignalError, SpecError

from .data import FlightData
from .model import ModelStructure, simulate_zoh
from .results import TFEstimate
from .srivc import srivc

__all__ = ["FitOptions", "tfest"]


@dataclass(frozen=True)
class FitOptions:
    """Settings of :func:`tfest`.

    Attributes
    ----------
    delay : float or "auto"
        Input delay in s (fixed), or ``"auto"`` to estimate it in ``[0, max_delay]``.
    max_delay : float
        Upper bound of the delay search, s.
    estimate_x0 : bool
        Estimate each experiment's initial state (else: the system starts at rest).
    max_iter : int
        IPOPT iteration limit.
    tol : float
        IPOPT tolerance (relative to the scaled problem).
    verbose : bool
        Print IPOPT's iteration log.
    """

    delay: float | str = 0.0
    max_delay: float = 0.3
    estimate_x0: bool = True
    max_iter: int = 300
    tol: float = 1e-10
    verbose: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.delay, str):
            if self.delay != "auto":
                raise SpecError(f"`delay`: got {self.delay!r}, expected a number of seconds >= 0 or 'auto'")
        elif not (math.isfinite(self.delay) and self.delay >= 0):
            raise SpecError(f"`delay`: got {self.delay!r}, expected a number of seconds >= 0 or 'auto'")
        if not (math.isfinite(self.max_delay) and self.max_delay >= 0):
            raise SpecError(f"`max_delay`: got {self.max_delay!r}, expected a number >= 0 (s)")
        if self.max_iter < 1:
            raise SpecError(f"`max_iter`: got {self.max_iter!r}, expected >= 1")


# ---------------------------------------------------------------- symbolic ZOH (CasADi)

def _sym_expm_aug(a, b, t: float | cs.SX, squarings: int, order: int = 10):
    """exp([[A, B], [0, 0]] t) -> (e^{At}, int_0^t e^{As} ds B), Taylor with scaling-squaring."""
    n = a.shape[0]
    m = cs.vertcat(cs.horzcat(a, b), cs.SX.zeros(1, n + 1)) * (t / 2**squarings)
    e = cs.SX.eye(n + 1)
    term = cs.SX.eye(n + 1)
    for k in range(1, order + 1):
        term = term @ m / k
        e = e + term
    for _ in range(squarings):
        e = e @ e
    return e[:n, :n], e[:n, n]


def _sym_companion(den_tail, num, n: int, n_num: int):
    a = cs.SX.zeros(n, n)
    for i in range(n - 1):
        a[i, i + 1] = 1
    for j in range(n):
        a[n - 1, j] = -den_tail[n - 1 - j]
    b = cs.SX.zeros(n, 1)
    b[n - 1] = 1
    c = cs.SX.zeros(1, n)
    for j in range(n_num):
        c[0, j] = num[n_num - 1 - j]
    return a, b, c


def _shift(u: np.ndarray, k: int) -> np.ndarray:
    return np.concatenate([np.zeros(k), u])[: u.size] if k > 0 else u


class _OEProblem:
    """The CasADi output-error problem for one integer delay ``nd``."""

    def __init__(self, structure: ModelStructure, exps: list[tuple[np.ndarray, np.ndarray]], ts: float,
                 nd: int, estimate_frac: bool, frac0: float, theta0: np.ndarray, opts: FitOptions):
        self.structure, self.exps, self.ts, self.nd = structure, exps, ts, nd
        n = structure.n_poles
        p = structure.n_params
        self.scale = np.maximum(np.abs(theta0), 1e-3 * max(1.0, float(np.max(np.abs(theta0)))))
        zs = cs.SX.sym("z", p)
        theta = zs * self.scale
        den_tail = cs.vertcat(theta[: structure.n_free_poles], cs.SX.zeros(structure.n_integrators, 1))
        num = theta[structure.n_free_poles:]
        a, b, c = _sym_companion(den_tail, num, n, structure.n_zeros + 1)
        fs = cs.SX.sym("f")
        frac_expr = fs if estimate_frac else cs.SX(frac0)
        # squarings from the initial estimate's spectral scale
        a0 = np.zeros((n, n))
        a0[:-1, 1:] = np.eye(n - 1)
        den0, _ = structure.split(theta0)
        a0[-1, :] = -den0[1:][::-1]
        norm = max(np.linalg.norm(a0, 1) * ts, 1e-12)
        sq = max(0, int(math.ceil(math.log2(norm / 0.1))) + 2)
        phi, g_full = _sym_expm_aug(a, b, ts, sq)
        if estimate_frac or frac0 > 0:
            phi_rest, g0 = _sym_expm_aug(a, b, ts - frac_expr, sq)
            _, gf = _sym_expm_aug(a, b, frac_expr, max(0, sq - 1))
            g1 = phi_rest @ gf
        else:
            g0, g1 = g_full, cs.SX.zeros(n, 1)
        # parameters -> sampled model, as one small SX function called from the MX graph
        model_fn = cs.Function("model", [zs, fs], [cs.vertcat(cs.vec(phi), g0, g1), c])
        x = cs.SX.sym("x", n)
        uu = cs.SX.sym("uu", 2)
        pars = cs.SX.sym("P", n * n + 2 * n)
        phi_p = cs.reshape(pars[: n * n], n, n)
        step = cs.Function("step", [x, uu, pars], [phi_p @ x + pars[n * n:n * n + n] * uu[0]
                                                   + pars[n * n + n:] * uu[1]])
        # the trajectory lives in an MX graph: mapaccum stays one call node (no scalar expansion)
        z = cs.MX.sym("z", p)
        frac = cs.MX.sym("f")
        pvec, c_mx = model_fn(z, frac if estimate_frac else cs.MX(frac0))
        variables = [z] + ([frac] if estimate_frac else [])
        x0s, resid, yhats = [], [], []
        for i, (u, y) in enumerate(exps):
            ud = _shift(u, nd)
            ud1 = _shift(ud, 1)
            nsteps = u.size
            x0 = cs.MX.sym(f"x0_{i}", n) if opts.estimate_x0 else cs.MX.zeros(n, 1)
            if opts.estimate_x0:
                x0s.append(x0)
            fmap = step.mapaccum(f"sim{i}", nsteps - 1)
            xs = fmap(x0, cs.DM(np.vstack([ud[:-1], ud1[:-1]])), cs.repmat(pvec, 1, nsteps - 1))
            xall = cs.horzcat(x0, xs)
            yhat = (c_mx @ xall).T
            yhats.append(yhat)
            resid.append(cs.DM(y) - yhat)
        self.n_x0 = len(x0s) * n
        self.y_scale = float(sum(np.sum((y - np.mean(y)) ** 2) for _, y in exps)) or 1.0
        self.w = cs.vertcat(*variables, *x0s)
        self.r = cs.vertcat(*resid)
        self.yhat = cs.vertcat(*yhats)
        self.n_theta = p
        self.estimate_frac = estimate_frac
        self.frac0 = frac0
        self.z0 = theta0 / self.scale

    def solve(self, opts: FitOptions, frac_init: float) -> tuple[np.ndarray, float, np.ndarray, float, dict]:
        f = 0.5 * cs.sumsqr(self.r) / self.y_scale
        nlp = {"x": self.w, "f": f}
        ipopt = {"print_level": 5 if opts.verbose else 0, "max_iter": opts.max_iter, "tol": opts.tol,
                 "acceptable_tol": 1e-8, "acceptable_iter": 5, "sb": "yes"}
        # Gauss-Newton Hessian J'J: positive semidefinite, so IPOPT takes full Newton-like steps
        # instead of crawling with inertia correction through indefinite regions
        lam_f = cs.MX.sym("lam_f")
        lam_g = cs.MX.sym("lam_g", 0)
        p = cs.MX.sym("p", 0)
        jr = cs.jacobian(self.r, self.w)
        hess = cs.triu(lam_f * (jr.T @ jr) / self.y_scale)
        hess_fn = cs.Function("nlp_hess_l", [self.w, p, lam_f, lam_g], [hess],
                              ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        solver = cs.nlpsol("oe", "ipopt", nlp, {"ipopt": ipopt, "print_time": opts.verbose,
                                               "show_eval_warnings": opts.verbose,
                                               "hess_lag": hess_fn})
        lbw = -np.inf * np.ones(self.w.shape[0])
        ubw = np.inf * np.ones(self.w.shape[0])
        w0 = np.zeros(self.w.shape[0])
        w0[: self.n_theta] = self.z0
        k = self.n_theta
        if self.estimate_frac:
            lbw[k], ubw[k], w0[k] = 0.0, self.ts, frac_init
            k += 1
        sol = solver(x0=w0, lbx=lbw, ubx=ubw)
        stats = solver.stats()
        wopt = np.asarray(sol["x"]).ravel()
        theta = wopt[: self.n_theta] * self.scale
        frac = float(wopt[self.n_theta]) if self.estimate_frac else self.frac0
        # Jacobian of the simulated output in the unscaled variables, for the covariance
        jac = -np.asarray(cs.Function("J", [self.w], [jr])(wopt))
        jac[:, : self.n_theta] /= self.scale
        return theta, frac, jac, float(sol["f"]) * 2 * self.y_scale, stats


# ---------------------------------------------------------------- initialisation

def _ls_numerator(structure: ModelStructure, free_den: np.ndarray, exps, ts: float, delay: float):
    """Numerator by linear least squares for a given free denominator; returns (theta, sse)."""
    cols_all, y_all = [], []
    n_num = structure.n_zeros + 1
    for u, y in exps:
        cols = []
        for j in range(n_num):
            unit = np.zeros(n_num)
            unit[n_num - 1 - j] = 1.0
            th = np.concatenate([free_den, unit])
            cols.append(simulate_zoh(structure, th, u, ts, delay))
        cols_all.append(np.column_stack(cols))
        y_all.append(y)
    phi, yy = np.vstack(cols_all), np.concatenate(y_all)
    b, *_ = np.linalg.lstsq(phi, yy, rcond=None)
    sse = float(np.sum((yy - phi @ b) ** 2))
    return np.concatenate([free_den, b[::-1]]), sse


def _grid_candidates(structure: ModelStructure, ts: float) -> list[np.ndarray]:
    nf = structure.n_free_poles
    if nf == 0:
        return [np.zeros(0)]
    nyq = np.pi / ts
    poles = np.geomspace(0.3, 0.5 * nyq, 9)
    out = [np.real(np.poly(np.full(nf, -p)))[1:] for p in poles]
    if nf >= 2:  # lightly damped pairs
        for wn in np.geomspace(1.0, 0.3 * nyq, 5):
            pair = [wn**2 * 0 + 1, 2 * 0.3 * wn, wn**2]
            rest = np.real(np.poly(np.full(nf - 2, -wn)))
            out.append(np.polymul(pair, rest)[1:])
    return out


def _sse(structure, theta, exps, ts, delay) -> float:
    """Simulation SSE of a candidate; unstable candidates that overflow count as infinite."""
    try:
        with np.errstate(over="ignore", invalid="ignore"):
            sse = float(sum(np.sum((y - simulate_zoh(structure, theta, u, ts, delay)) ** 2) for u, y in exps))
    except (ValueError, np.linalg.LinAlgError, OverflowError):
        return np.inf
    return sse if np.isfinite(sse) else np.inf


def _initialise(structure, exps, ts, delays, progress, keep: int = 1):
    """Best initial estimate per delay; returns the ``keep`` best ``(sse, theta, delay)`` with
    distinct integer delays, best first."""
    per_delay = []
    for d in delays:
        cands = []
        try:
            cands.append(srivc(structure, exps, ts, delay=d))
        except (np.linalg.LinAlgError, ValueError):
            pass
        for free in _grid_candidates(structure, ts):
            theta, sse = _ls_numerator(structure, free, exps, ts, d)
            cands.append(theta)
        best = (np.inf, None, d)
        for theta in cands:
            if not np.all(np.isfinite(theta)):
                continue
            sse = _sse(structure, theta, exps, ts, d)
            if sse < best[0]:
                best = (sse, theta, d)
        if best[1] is not None:
            per_delay.append(best)
    if not per_delay:
        raise IlcdobError("no initial estimate could be formed: check that the input excites the system")
    per_delay.sort(key=lambda c: c[0])
    chosen, seen = [], set()
    for cand in per_delay:
        nd = int(math.floor(cand[2] / ts + 1e-9))
        if nd not in seen:
            seen.add(nd)
            chosen.append(cand)
        if len(chosen) == keep:
            break
    progress("initial estimate(s): " + ", ".join(f"delay {c[2]:.4g} s (SSE {c[0]:.4g})" for c in chosen))
    return chosen


# ---------------------------------------------------------------- public entry

def _experiments(data, input: str, output: str, structure: ModelStructure, opts: FitOptions):
    if isinstance(data, FlightData):
        data = [data]
    if not data:
        raise SignalError("`data`: no experiments given")
    ts = data[0].ts
    exps = []
    for fd in data:
        if abs(fd.ts - ts) > 1e-9 * ts:
            raise SignalError(f"{fd.source}: sample time {fd.ts} s differs from {data[0].source} ({ts} s); "
                              "resample to one grid first")
        u, y = fd[input], fd[output]
        need = 10 * (structure.n_params + structure.n_poles)
        if u.size < need:
            raise SignalError(f"{fd.source}: {u.size} samples are too few for a model with "
                              f"{structure.n_params} parameters (need at least {need})")
        if np.std(u) == 0:
            raise SignalError(f"{fd.source}: input `{input}` is constant: it does not excite the system")
        exps.append((u, y))
    return exps, ts


def tfest(data: FlightData | list[FlightData], input: str, output: str, structure: ModelStructure,
          options: FitOptions | None = None, validation: FlightData | list[FlightData] | None = None,
          progress: Callable[[str], None] | None = None) -> TFEstimate:
    """Fit a continuous-time transfer function to one or several experiments.

    Parameters
    ----------
    data : FlightData or list of FlightData
        Estimation experiments (same sample time); fitted jointly.
    input, output : str
        Signal names of the plant input (e.g. commanded acceleration, m/s^2) and output
        (e.g. position, m).
    structure : ModelStructure
        Poles (incl. fixed integrators), zeros, integrators.
    options : FitOptions
    validation : FlightData or list, optional
        Held-out experiments: their fit percent is reported (initial state estimated there
        too, by linear least squares, as MATLAB's ``compare`` does).
    progress : callable, optional
        Receives progress lines (default: stderr).

    Returns
    -------
    TFEstimate
    """
    opts = options or FitOptions()
    say = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
    exps, ts = _experiments(data, input, output, structure, opts)
    t_start = time.perf_counter()
    if opts.delay == "auto":
        delays = np.arange(0.0, opts.max_delay + 1e-12, ts / 2)
    else:
        delays = [float(opts.delay)]
    estimate_delay = opts.delay == "auto"
    # delay and lag trade off: refine the three best delays of the scan, keep the best fit
    starts = _initialise(structure, exps, ts, delays, say, keep=3 if estimate_delay else 1)
    best = None
    tried: set[int] = set()
    for _, theta0, d0 in starts:
        nd = int(math.floor(d0 / ts + 1e-9))
        frac0 = d0 - nd * ts
        while nd not in tried and nd >= 0:
            tried.add(nd)
            prob = _OEProblem(structure, exps, ts, nd, estimate_delay, frac0, theta0, opts)
            theta, frac, jac, sse, stats = prob.solve(opts, frac0)
            say(f"IPOPT (integer delay {nd} samples): {stats['return_status']}, {stats['iter_count']} "
                f"iterations, SSE {sse:.6g}")
            ok = stats["success"] or stats["return_status"] == "Solved_To_Acceptable_Level"
            if ok and (best is None or sse < best[3]):
                best = (theta, nd * ts + frac, jac, sse, stats, prob)
            if not estimate_delay:
                break
            # fractional part at a bound: the optimum may lie in the neighbouring sample
            if frac >= ts * (1 - 1e-3):
                nd, frac0 = nd + 1, 0.0
            elif frac <= ts * 1e-3 and nd > 0:
                nd, frac0 = nd - 1, ts
            else:
                break
            theta0 = theta
    if best is None:
        raise IlcdobError(f"IPOPT did not converge ({stats['return_status']}); try another model order, "
                          "more excitation, or options.verbose=True to see the iterations")
    theta, delay, jac, sse, stats, prob = best
    n_obs = sum(u.size for u, _ in exps)
    n_var = jac.shape[1]
    sigma2 = sse / max(n_obs - n_var, 1)
    jtj = jac.T @ jac
    cov_all = sigma2 * np.linalg.pinv(jtj)
    n_keep = structure.n_params + (1 if estimate_delay else 0)
    cov = cov_all[:n_keep, :n_keep]
    return TFEstimate.from_fit(structure=structure, theta=theta, delay=delay, covariance=cov,
                               delay_estimated=estimate_delay, sigma2=sigma2, experiments=exps, ts=ts,
                               validation=validation, input=input, output=output,
                               solver={"status": stats["return_status"], "iterations": stats["iter_count"],
                                       "seconds": time.perf_counter() - t_start})
