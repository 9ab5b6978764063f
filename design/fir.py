"""Implementable learning filters: fixed-order non-causal FIRs fitted with CasADi/IPOPT.

The closed-form filters of the Theorem (docs/theory.md section 2, :mod:`ilcdob.design.closed_form`)
are rational, improper and partly anti-causal. Here each of them is replaced by a FIR with a
fixed non-causal advance ``a`` (samples)::

    output(k) = sum_{i=0}^{n-1} h[i] * input(k + a - i)        H(z) = z^a * sum_i h[i] z^-i

whose coefficients solve (CasADi ``nlpsol`` with IPOPT) a weighted least-squares fit to the
ideal response ``L(e^{jw Ts})`` on a log grid ``w_min <= w <= w_max`` (default: Nyquist)::

    minimise    sum_w  weight(w) |H(e^{jw Ts}) - L(e^{jw Ts})|^2 / |L(e^{jw Ts})|^2  /  n_grid
              + ridge * ||h / s||^2                          (s: scale of h, conditioning)
    subject to  |Te1_k(e^{jw Ts})| <= 1 - margin    for every model k and grid frequency w   (L1 only)
    with        Te1_k = Gd_j^k / Gd_{j-1}^k - Gf_j^k H        (the k-th sampled true loops of
                                                               both systems, paired)

i.e. robust monotone convergence of the error map of the Theorem over the Delta set
(docs/theory.md section 3). The relative (``1/|L|^2``) weighting makes the fit scale-free: ``|L1|`` spans
five decades between ``w_min`` and Nyquist (an inverse plant at high frequency). ``weight(w)``
is ``band_weight`` inside ``weight_band`` and 1 elsewhere.

DC and the integrator of L1. ``L1 = -(1 - Q_j) Gd_{j-1}^{-1}`` keeps the PID integrator of
system j-1 (a pole at z = 1, visible below about ``ki/kp`` rad/s), which a FIR, with its
finite DC gain, cannot reproduce. The fit and the constraint therefore start at
``w_min > 0`` (choose it below the lowest disturbance frequency of interest). Below
``w_min`` nothing is promised: as ``w -> 0``, ``Gf_j H -> 0`` and ``Te1 -> lim Gd_j/Gd_{j-1}
= ki_{j-1}/ki_j`` (same Q), which exceeds 1 when system j-1 has the larger integral gain.
The design reports ``|Te1|`` below the band (:attr:`FIRDesign.te1_below_band`) so the user
sees it; in practice slow drifts are left to each system's own integrator and DOB.

L2 (``L1 Gf_{j-1}``, finite at DC and at Nyquist) is fitted the same way without constraint.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as cs
import numpy as np

from ilcdob.errors import IlcdobError, SpecError
from ilcdob.interrupts import honour_interrupts
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.signals import as_signal, extend_smoothly

from .closed_form import LearningFilters, closed_form_filters
from .delta import DeltaSet

__all__ = ["FIROptions", "FIRFilter", "FIRDesign", "FIRDesignError", "design_fir", "fit_fir"]


class FIRDesignError(IlcdobError, ValueError):
    """The robust convergence constraint cannot be met by the FIR of the given order."""


@dataclass(frozen=True)
class FIROptions:
    """Options of :func:`design_fir` (module docstring gives the optimisation problem).

    Attributes
    ----------
    n_taps : int
        FIR length ``n`` (>= 2).
    advance : int
        Non-causal lead ``a`` in samples, ``0 <= a <= n_taps - 1``.
    w_min : float
        Lowest grid frequency, rad/s (> 0; the integrator of L1 is not fitted below it).
    w_max : float or None
        Highest grid frequency, rad/s (default ``0.999 * pi / Ts``, just below Nyquist).
    n_grid : int
        Number of log-spaced grid frequencies (>= 10).
    margin : float
        Robust monotone convergence margin: ``|Te1| <= 1 - margin``, ``0 <= margin < 1``.
    weight_band : tuple of float
        Frequencies ``(lo, hi)`` rad/s where the fit is emphasised by ``band_weight``.
    band_weight : float
        Multiplier (> 0) of the relative fit weight inside ``weight_band``.
    ridge : float
        Tikhonov weight (>= 0) on the scaled coefficients; tames the huge cancelling
        coefficients of a long FIR fitting an inverse plant.
    max_iter : int
        IPOPT iteration limit.
    """

    n_taps: int = 80
    advance: int = 8
    w_min: float = 0.3
    w_max: float | None = None
    n_grid: int = 200
    margin: float = 0.1
    weight_band: tuple[float, float] = (0.3, 5.0)
    band_weight: float = 10.0
    ridge: float = 1e-8
    max_iter: int = 300

    def __post_init__(self) -> None:
        if not (isinstance(self.n_taps, (int, np.integer)) and self.n_taps >= 2):
            raise SpecError(f"`n_taps`: got {self.n_taps!r}, expected an integer >= 2")
        if not (isinstance(self.advance, (int, np.integer)) and 0 <= self.advance <= self.n_taps - 1):
            raise SpecError(f"`advance`: got {self.advance!r}, expected an integer in [0, n_taps - 1 = "
                            f"{self.n_taps - 1}]")
        if not (np.isfinite(self.w_min) and self.w_min > 0):
            raise SpecError(f"`w_min`: got {self.w_min!r}, expected a frequency > 0 rad/s (a FIR cannot "
                            "match the integrator of L1 at DC)")
        if self.w_max is not None and not (np.isfinite(self.w_max) and self.w_max > self.w_min):
            raise SpecError(f"`w_max`: got {self.w_max!r}, expected > w_min = {self.w_min} rad/s or None")
        if not (isinstance(self.n_grid, (int, np.integer)) and self.n_grid >= 10):
            raise SpecError(f"`n_grid`: got {self.n_grid!r}, expected an integer >= 10")
        if not (np.isfinite(self.margin) and 0 <= self.margin < 1):
            raise SpecError(f"`margin`: got {self.margin!r}, expected 0 <= margin < 1")
        lo_hi = tuple(self.weight_band)
        if len(lo_hi) != 2 or not (0 <= lo_hi[0] < lo_hi[1]):
            raise SpecError(f"`weight_band`: got {self.weight_band!r}, expected (lo, hi) with 0 <= lo < hi")
        if not (np.isfinite(self.band_weight) and self.band_weight > 0):
            raise SpecError(f"`band_weight`: got {self.band_weight!r}, expected > 0")
        if not (np.isfinite(self.ridge) and self.ridge >= 0):
            raise SpecError(f"`ridge`: got {self.ridge!r}, expected >= 0")
        if not (isinstance(self.max_iter, (int, np.integer)) and self.max_iter >= 1):
            raise SpecError(f"`max_iter`: got {self.max_iter!r}, expected an integer >= 1")

    def grid(self, ts: float) -> np.ndarray:
        """Log-spaced design grid from ``w_min`` to ``w_max``.

        Parameters
        ----------
        ts : float
            Sample time, s (gives the default ``w_max``, just below Nyquist).

        Returns
        -------
        numpy.ndarray
            ``n_grid`` frequencies, rad/s.

        Raises
        ------
        SpecError
            ``w_max`` above Nyquist or not above ``w_min``.
        """
        nyq = 0.999 * np.pi / ts
        w_max = nyq if self.w_max is None else float(self.w_max)
        if w_max > np.pi / ts or self.w_min >= w_max:
            raise SpecError(f"`w_min`/`w_max`: need w_min = {self.w_min} < w_max = {w_max} <= Nyquist "
                            f"{np.pi / ts:.4g} rad/s; lower w_min or raise w_max")
        return np.logspace(np.log10(self.w_min), np.log10(w_max), self.n_grid)

    def weights(self, w: np.ndarray) -> np.ndarray:
        """Band emphasis ``weight(w)``: ``band_weight`` inside ``weight_band``, 1 elsewhere.

        Parameters
        ----------
        w : numpy.ndarray
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            The weights, the shape of ``w``.
        """
        lo, hi = self.weight_band
        return np.where((w >= lo) & (w <= hi), self.band_weight, 1.0)


@dataclass(frozen=True)
class FIRFilter:
    """A non-causal FIR ``output(k) = sum_i h[i] input(k + advance - i)``.

    Attributes
    ----------
    h : numpy.ndarray
        Coefficients ``h[0..n-1]`` (``h[0]`` multiplies ``input(k + advance)``).
    advance : int
        Non-causal lead, samples.
    ts : float
        Sample time, s.
    fit_error : float
        Weighted relative RMS fit error on the design grid (``nan`` if not fitted).
    max_rel_error : float
        Largest ``|H - L| / |L|`` on the design grid.
    """

    h: np.ndarray
    advance: int
    ts: float
    fit_error: float = float("nan")
    max_rel_error: float = float("nan")

    def __post_init__(self) -> None:
        h = np.asarray(self.h, dtype=float)
        if h.ndim != 1 or h.size < 1 or not np.all(np.isfinite(h)):
            raise SpecError(f"`h`: expected a 1-D finite array of coefficients, got shape {h.shape}")
        if not (0 <= int(self.advance)):
            raise SpecError(f"`advance`: got {self.advance!r}, expected >= 0 samples")
        if not (np.isfinite(self.ts) and self.ts > 0):
            raise SpecError(f"`ts`: got {self.ts!r}, expected a sample time > 0 s")
        object.__setattr__(self, "h", h)
        object.__setattr__(self, "advance", int(self.advance))

    @property
    def n_taps(self) -> int:
        """Number of coefficients ``n``."""
        return int(self.h.size)

    def freqresp(self, w: np.ndarray) -> np.ndarray:
        """Frequency response ``H(e^{jw Ts}) = e^{jw Ts a} sum_i h[i] e^{-jw Ts i}``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        w = np.asarray(w, dtype=float)
        return _fir_matrix(w.reshape(-1), self.n_taps, self.advance, self.ts).dot(self.h).reshape(w.shape)

    def apply(self, x: object, name: str = "x") -> np.ndarray:
        """Apply non-causally over a whole trial.

        Before the trial the input is taken as zero (the system starts at rest); the
        ``advance`` samples needed past its end continue the input by a cubic fitted to the
        last samples (:func:`ilcdob.signals.extend_smoothly`), never by zeros (a step into a
        differentiating filter would spike).

        Parameters
        ----------
        x : array_like
            The trial, one sample per sample time.
        name : str
            The signal's name, for error messages.

        Returns
        -------
        numpy.ndarray
            The filtered trial, same length.
        """
        x = as_signal(x, name)
        n, m = x.size, self.n_taps
        z = np.concatenate([np.zeros(m - 1), extend_smoothly(x, self.advance)])
        full = np.convolve(z, self.h)
        start = m - 1 + self.advance
        return full[start:start + n]

    def to_dict(self) -> dict:
        """The filter in the coefficient form of ``filters.json`` (:mod:`.export`).

        ``num`` lists the coefficients of ``z^0, z^-1, ...`` (highest power first), so
        ``output(k) = sum_i num[i] * input(k + advance - i)``.

        Returns
        -------
        dict
            ``{"num": [...], "den": [1.0], "advance": a, "ts": Ts}``:
            ``H(z) = z^a sum_i num[i] z^-i``.
        """
        return {"num": [float(v) for v in self.h], "den": [1.0], "advance": int(self.advance),
                "ts": float(self.ts)}


@dataclass(frozen=True)
class FIRDesign:
    """The FIR pair replacing the closed-form (L1, L2) of one learning step j-1 -> j.

    Attributes
    ----------
    source, target : str
        Names of systems j-1 and j.
    L1, L2 : FIRFilter
        The filters replacing the closed-form ``L1`` and ``L2``.
    w : numpy.ndarray
        Design grid, rad/s.
    te1 : numpy.ndarray
        ``|Te1_k(w)|`` (K x len(w)) with the FIR L1 and the sampled true loops.
    worst_te1 : float
        ``max |Te1|`` on the grid (<= 1 - margin when the design succeeded).
    worst_w : float
        Frequency of ``worst_te1``, rad/s.
    worst_model : int
        Index k of the sampled model pair attaining it.
    te1_below_band : float
        ``max |Te1|`` over models on a check grid from 1e-3 rad/s to ``w_min`` (not
        constrained, see module docstring: the FIR has no integrator).
    options : FIROptions
        The options of the design.
    solver_status : str
        IPOPT's return status for L1.
    """

    source: str
    target: str
    L1: FIRFilter
    L2: FIRFilter
    w: np.ndarray
    te1: np.ndarray
    worst_te1: float
    worst_w: float
    worst_model: int
    te1_below_band: float
    options: FIROptions
    solver_status: str = field(default="")

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of system j: ``L1{e_{j-1}} + L2{d_f,{j-1}}`` (the Theorem, paper Sec. III).

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1 over the trial, m.
        df_prev : array_like
            Learning signal system j-1 flew with, m/s^2 (zeros if none), same length.

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2, same length.
        """
        e = as_signal(e_prev, "e_prev")
        df = as_signal(df_prev, "df_prev", e.size)
        out = self.L1.apply(e, "e_prev")
        return out + self.L2.apply(df, "df_prev") if np.any(df) else out

    def to_dict(self) -> dict:
        """The design as a JSON-ready dict.

        Returns
        -------
        dict
            ``source``, ``target``, both filters (:meth:`FIRFilter.to_dict`), the worst
            ``|Te1|`` with its frequency and model, ``te1_below_band`` and both fit errors.
        """
        return {"source": self.source, "target": self.target, "L1": self.L1.to_dict(),
                "L2": self.L2.to_dict(), "worst_te1": self.worst_te1, "worst_w": self.worst_w,
                "worst_model": self.worst_model, "te1_below_band": self.te1_below_band,
                "fit_error_L1": self.L1.fit_error, "fit_error_L2": self.L2.fit_error}


def _fir_matrix(w: np.ndarray, n: int, advance: int, ts: float) -> np.ndarray:
    """Rows ``e^{-jw Ts (i - a)}``, i = 0..n-1, so that ``H(w) = E @ h``."""
    return np.exp(-1j * np.outer(np.asarray(w, float) * ts, np.arange(n) - advance))


def _realify(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a.real, a.imag], axis=0)


def fit_fir(target: np.ndarray, w: np.ndarray, ts: float, options: FIROptions,
            te_const: np.ndarray | None = None, te_gain: np.ndarray | None = None
            ) -> tuple[FIRFilter, np.ndarray, str, bool]:
    """Fit a FIR to the response ``target`` on ``w`` with CasADi/IPOPT.

    Parameters
    ----------
    target : complex array
        Ideal response on ``w``.
    w : array, rad/s
    ts : float
    options : FIROptions
    te_const, te_gain : complex arrays (K x len(w)), optional
        Constraint ``|te_const - te_gain * H| <= 1 - margin`` (Te1 of the module docstring);
        omitted: unconstrained fit.

    Returns
    -------
    (FIRFilter, |Te|, IPOPT status, success)
        ``|Te|`` is K x len(w) (empty without constraint). The fit is ill-conditioned (the
        ideal response spans decades), so IPOPT may stop at its iteration limit near the
        optimum; callers judge the returned point by the constraint, not by the status.
    """
    n, adv = int(options.n_taps), int(options.advance)
    e_mat = _fir_matrix(w, n, adv, ts)
    mag = np.abs(target)
    if np.any(mag == 0) or not np.all(np.isfinite(target)):
        raise SpecError("`target`: the ideal response has zeros or non-finite values on the grid; "
                        "move w_min/w_max away from them")
    wt = np.sqrt(options.weights(w) / w.size) / mag
    # initial guess and scale: ridge-regularised linear least squares (numpy)
    a_fit = _realify(e_mat * wt[:, None])
    y_fit = _realify(target * wt)
    s = float(np.max(mag))
    a_s = a_fit * s
    reg = np.sqrt(max(options.ridge, 1e-14)) * np.eye(n)
    x0 = np.linalg.lstsq(np.vstack([a_s, reg]), np.concatenate([y_fit, np.zeros(n)]), rcond=None)[0]

    x = cs.MX.sym("x", n)
    obj = cs.sumsqr(cs.mtimes(cs.DM(a_s), x) - cs.DM(y_fit)) + options.ridge * cs.sumsqr(x)
    nlp = {"x": x, "f": obj}
    lbg = ubg = None
    if te_const is not None:
        gain = np.asarray(te_gain, complex)
        const = np.asarray(te_const, complex)
        b = (gain[:, :, None] * e_mat[None, :, :]).reshape(-1, n) * s
        c = const.reshape(-1)
        re = cs.DM(c.real) - cs.mtimes(cs.DM(b.real), x)
        im = cs.DM(c.imag) - cs.mtimes(cs.DM(b.imag), x)
        nlp["g"] = re**2 + im**2
        lbg = -np.inf * np.ones(c.size)
        ubg = (1.0 - options.margin) ** 2 * np.ones(c.size)
    solver = cs.nlpsol("fir_fit", "ipopt", nlp, {
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
        "ipopt.max_iter": int(options.max_iter), "ipopt.tol": 1e-8,
        "ipopt.acceptable_tol": 1e-6, "ipopt.acceptable_iter": 5})
    args = {"x0": x0}
    if lbg is not None:
        args.update(lbg=lbg, ubg=ubg)
    with honour_interrupts():  # CasADi turns a Ctrl-C into a failed solve
        sol = solver(**args)
    stats = solver.stats()
    status = str(stats.get("return_status", ""))
    h = np.asarray(sol["x"], float).reshape(-1) * s
    resp = e_mat @ h
    rel = np.abs(resp - target) / mag
    fit = float(np.sqrt(np.sum(options.weights(w) * rel**2) / np.sum(options.weights(w))))
    te = np.zeros((0, w.size))
    if te_const is not None:
        te = np.abs(np.asarray(te_const) - np.asarray(te_gain) * resp[None, :])
    ok = bool(stats.get("success", False)) or status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    return FIRFilter(h, adv, ts, fit, float(np.max(rel))), te, status, ok


def _models(loop: LoopSystem, delta: DeltaSet | None, which: str) -> tuple[LoopSystem, ...]:
    if delta is None:
        return (loop,)
    if not isinstance(delta, DeltaSet):
        raise SpecError(f"`{which}`: expected a DeltaSet (ilcdob.design.delta_set) or None, "
                        f"got {type(delta).__name__}")
    if delta.system != loop.name:
        raise SpecError(f"`{which}`: Delta set of system {delta.system!r} given for loop {loop.name!r}; "
                        "pass the Delta set of the same system")
    return tuple(delta.loops)


def design_fir(prev_loop: LoopSystem, next_loop: LoopSystem, delta_prev: DeltaSet | None = None,
               delta_next: DeltaSet | None = None, options: FIROptions | None = None) -> FIRDesign:
    """FIR learning filters for system ``next_loop`` (j) learning from ``prev_loop`` (j-1).

    L1 is fitted to ``closed_form_filters(prev_loop, next_loop).l1_response`` subject to
    robust monotone convergence ``|Te1_k| <= 1 - margin`` for every pair ``k`` of sampled
    true loops (``delta_prev.loops[k]``, ``delta_next.loops[k]``) on the grid; L2 is fitted to
    ``l2_response`` without constraint (module docstring; docs/theory.md sections 2-3).

    Parameters
    ----------
    prev_loop, next_loop : LoopSystem
    delta_prev, delta_next : DeltaSet or None
        Sampled true loops of both systems, the same number K of each (None: the model only).
    options : FIROptions, optional

    Raises
    ------
    SpecError
        Bad options, mismatched Delta sets or sample times.
    FIRDesignError
        The constraint cannot be met; the message names the worst frequency and model.
    """
    options = FIROptions() if options is None else options
    if not isinstance(options, FIROptions):
        raise SpecError(f"`options`: expected FIROptions, got {type(options).__name__}")
    filters: LearningFilters = closed_form_filters(prev_loop, next_loop)
    ts = prev_loop.ts
    w = options.grid(ts)
    src_models = _models(prev_loop, delta_prev, "delta_prev")
    tgt_models = _models(next_loop, delta_next, "delta_next")
    if delta_prev is None and delta_next is not None:
        src_models = (prev_loop,) * len(tgt_models)
    if delta_next is None and delta_prev is not None:
        tgt_models = (next_loop,) * len(src_models)
    if len(src_models) != len(tgt_models):
        raise SpecError(f"`delta_prev`/`delta_next`: {len(src_models)} and {len(tgt_models)} samples; the "
                        "k-th samples are paired, draw both Delta sets with the same k")
    const = np.array([freqresp(t.G_d, w) / freqresp(s.G_d, w) for s, t in zip(src_models, tgt_models)])
    gain = np.array([freqresp(t.G_f, w) for t in tgt_models])
    l1_fir, te, status, _converged = fit_fir(filters.l1_response(w), w, ts, options, const, gain)
    k, i = np.unravel_index(int(np.argmax(te)), te.shape)
    worst = float(te[k, i])
    limit = 1.0 - options.margin
    if worst > limit * (1 + 1e-6):  # judged on the returned point, whatever IPOPT's status
        raise FIRDesignError(
            f"FIR learning filter {prev_loop.name!r} -> {next_loop.name!r}: robust monotone convergence "
            f"|Te1| <= {limit:.3g} not met (IPOPT: {status}); worst |Te1| = {worst:.4g} at w = "
            f"{w[i]:.4g} rad/s for sampled model {k}. Next step: more taps (n_taps = {options.n_taps}), "
            f"a larger advance ({options.advance}), a larger w_min ({options.w_min} rad/s), a smaller "
            f"margin ({options.margin}) or a smaller uncertainty.")
    w_low = np.logspace(-3, np.log10(options.w_min), 40)
    const_low = np.array([freqresp(t.G_d, w_low) / freqresp(s.G_d, w_low)
                          for s, t in zip(src_models, tgt_models)])
    gain_low = np.array([freqresp(t.G_f, w_low) for t in tgt_models])
    te_low = float(np.max(np.abs(const_low - gain_low * l1_fir.freqresp(w_low)[None, :])))
    l2_fir, _, _, _ = fit_fir(filters.l2_response(w), w, ts, options)
    return FIRDesign(source=prev_loop.name, target=next_loop.name, L1=l1_fir, L2=l2_fir, w=w, te1=te,
                     worst_te1=worst, worst_w=float(w[i]), worst_model=int(k), te1_below_band=te_low,
                     options=options, solver_status=status)
