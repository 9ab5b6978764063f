"""The result of a transfer-function fit: model, fit, covariance, residual tests, uncertainty.

Modelled on MATLAB's ``tfest`` / ``compare`` / ``resid`` / ``getcov`` and on the estimator
pattern (fitted quantities as attributes; ``predict``, ``score``). ``fit_percent`` is
MATLAB's normalised RMSE fit ``100 (1 - ||y - yhat|| / ||y - mean(y)||)``, with each
experiment's initial state estimated by linear least squares, as ``compare`` does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ilcdob.display import html_table, polynomial_text as _poly, time_text
from ilcdob.signals import FlightData
from ilcdob.specs import IdentificationSpec
from ilcdob.uncertainty import ModelStructure, frequency_response, multiplicative_bound

from .oe import discretise, response, simulate_zoh

if TYPE_CHECKING:
    import control as ct

__all__ = ["TFEstimate", "ResidualTest", "compare", "trend_basis", "fit_percent", "free_response_basis",
           "MARGINAL_DAMPING", "unidentified_poles", "pole_std"]


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """MATLAB's fit: ``100 * (1 - ||y - yhat|| / ||y - mean(y)||)``, in %.

    Parameters
    ----------
    y : array_like
        Measured output.
    yhat : array_like
        Model output, same length.

    Returns
    -------
    float
        The fit, % (100: exact; ``nan`` for a constant ``y``).
    """
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    den = np.linalg.norm(y - np.mean(y))
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / den)) if den > 0 else float("nan")


def free_response_basis(structure: ModelStructure, theta: np.ndarray, ts: float, n: int) -> np.ndarray:
    """Free responses of the model: the output from each unit initial state, zero input.

    Parameters
    ----------
    structure : ModelStructure
        The model's orders.
    theta : numpy.ndarray
        Its parameters.
    ts : float
        Sample time, s.
    n : int
        Number of samples.

    Returns
    -------
    numpy.ndarray
        ``n x states``, one column per companion-form state, computed by filtering.
    """
    d = discretise(structure, theta, ts, 0.0, derivatives=False)
    eye = np.eye(d.phi.shape[0])
    return np.column_stack([response(d.phi, d.c[0], d.sos, d.den, n, (), eye[i]) for i in range(eye.shape[0])])


@dataclass(frozen=True)
class ResidualTest:
    """A correlation test of the residuals (MATLAB ``resid``), at the 99 % level.

    Attributes
    ----------
    lags : array of int
        Lags, samples.
    values : array
        Normalised correlation at each lag.
    bound : float
        ``2.58 / sqrt(N)``: the 99 % band for white, independent signals.
    """

    lags: np.ndarray
    values: np.ndarray
    bound: float

    @property
    def share_inside(self) -> float:
        """Fraction of lags inside the band (about 0.99 expected when the test passes)."""
        return float(np.mean(np.abs(self.values) <= self.bound))

    @property
    def passed(self) -> bool:
        """At most 5 % of the lags outside the 99 % band."""
        return self.share_inside >= 0.95


def _xcorr(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation ``sum_k a[k] b[k - lag]`` at each lag."""
    a = a - a.mean()
    b = b - b.mean()
    n = a.size
    norm = np.sqrt((a @ a) * (b @ b))
    return np.array([a[k:] @ b[: n - k] if k >= 0 else a[: n + k] @ b[-k:] for k in lags]) / norm


@dataclass(frozen=True)
class TFEstimate:
    """A fitted continuous-time transfer function ``B(s)/(s^K A(s)) e^{-s delay}``.

    Attributes
    ----------
    structure : ModelStructure
        The model's orders.
    theta : array
        Parameters (free denominator coefficients, then numerator), see ``structure``.
    num, den : array
        s-polynomials, highest power first, denominator monic.
    delay : float
        Input delay, s.
    covariance : array
        Covariance of ``theta`` (and of ``delay`` as last row/column when it was estimated).
    delay_estimated : bool
        Whether the delay was estimated (then it has a row/column in ``covariance``).
    sigma2 : float
        Residual variance of the estimation data.
    ts : float
        Sample time of the data, s.
    fit_estimation : float
        Fit % on the estimation experiments (all samples pooled).
    fit_validation : float or None
        Fit % on held-out experiments.
    whiteness : ResidualTest
        Residual autocorrelation, lags 1..25.
    input_correlation : ResidualTest
        Input-residual cross-correlation, lags -25..25.
    input, output : str
        Names of the input and output signals in the data.
    solver : dict
        Engine, status (``converged``, ``max_iter``, ``time_limit``), iterations, starts and
        wall time.
    trend : int or None
        Degree of the per-experiment output trend that was estimated (None: none), also
        estimated in :meth:`predict` with ``y`` and in the validation fit.
    file_fits : list of float
        Fit % of each estimation experiment on its own.
    diagnostics : list of str
        What a careful engineer would want to know about the fit (:func:`fit_diagnostics`);
        empty when nothing stands out.
    fit_validation_rest : float or None
        Fit % on the held-out experiments simulated from rest (the trend still fitted, the initial state
        not: :func:`compare` with ``initial_state=False``), beside :attr:`fit_validation`, whose initial state is
        refitted.
    """

    structure: ModelStructure
    theta: np.ndarray
    num: np.ndarray
    den: np.ndarray
    delay: float
    covariance: np.ndarray
    delay_estimated: bool
    sigma2: float
    ts: float
    fit_estimation: float
    fit_validation: float | None
    whiteness: ResidualTest
    input_correlation: ResidualTest
    input: str = "u"
    output: str = "y"
    solver: dict = field(default_factory=dict)
    trend: int | None = None
    file_fits: list = field(default_factory=list)
    diagnostics: list = field(default_factory=list)
    fit_validation_rest: float | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_fit(cls, *, structure, theta, delay, covariance, delay_estimated, sigma2, experiments, ts,
                 validation, input, output, solver, trend=None, fitted=None) -> "TFEstimate":
        """Assemble the result of a fit: fits, residual tests and the validation fit.

        Parameters
        ----------
        structure : ModelStructure
            The model's orders.
        theta : array_like
            Fitted parameters.
        delay : float
            Input delay, s.
        covariance : array_like
            Covariance of ``theta`` (and of the delay, last, when estimated).
        delay_estimated : bool
            Whether the delay was estimated.
        sigma2 : float
            Residual variance.
        experiments : list of (numpy.ndarray, numpy.ndarray)
            The estimation data, ``(u, y)`` per experiment.
        ts : float
            Sample time, s.
        validation : FlightData or list of FlightData or None
            Held-out experiments (their fit is computed with :func:`compare`).
        input, output : str
            Signal names of the input and output.
        solver : dict
            Solver report (engine, status, iterations, starts, wall time).
        trend : int or None
            Degree of the per-experiment output trend.
        fitted : list of numpy.ndarray, optional
            The model output per experiment, when the fit has it (spares recomputing the
            estimation data's :func:`compare`).

        Returns
        -------
        TFEstimate
            The result.
        """
        den, num = structure.split(theta)
        ys, yhats, us = [], [], []
        for i, (u, y) in enumerate(experiments):
            ys.append(y)
            yhats.append(fitted[i] if fitted is not None else compare(structure, theta, delay, ts, u, y, trend))
            us.append(u)
        y_all, yh_all, u_all = np.concatenate(ys), np.concatenate(yhats), np.concatenate(us)
        resid = y_all - yh_all
        lags = np.arange(1, 26)
        bound = 2.58 / np.sqrt(resid.size)
        white = ResidualTest(lags, _xcorr(resid, resid, lags), bound)
        xl = np.arange(-25, 26)
        xcor = ResidualTest(xl, _xcorr(resid, u_all, xl), bound)
        fit_val = fit_rest = None
        if validation is not None:
            vals = [validation] if isinstance(validation, FlightData) else list(validation)
            yv, yhv, yrv = [], [], []
            for fd in vals:
                u = fd[input]
                yv.append(fd[output])
                yhv.append(compare(structure, theta, delay, fd.ts, u, fd[output], trend))
                yrv.append(compare(structure, theta, delay, fd.ts, u, fd[output], trend, initial_state=False))
            fit_val = fit_percent(np.concatenate(yv), np.concatenate(yhv))
            fit_rest = fit_percent(np.concatenate(yv), np.concatenate(yrv))
        file_fits = [fit_percent(y, yh) for y, yh in zip(ys, yhats)]
        est = cls(structure=structure, theta=np.asarray(theta, float), num=num, den=den, delay=float(delay),
                  covariance=np.asarray(covariance, float), delay_estimated=bool(delay_estimated),
                  sigma2=float(sigma2), ts=float(ts), fit_estimation=fit_percent(y_all, yh_all),
                  fit_validation=fit_val, whiteness=white, input_correlation=xcor, input=input,
                  output=output, solver=dict(solver), trend=trend, file_fits=file_fits, fit_validation_rest=fit_rest)
        est.diagnostics.extend(fit_diagnostics(est))
        return est

    # ------------------------------------------------------------------ use
    @property
    def model(self) -> ct.TransferFunction:
        """python-control transfer function ``num(s)/den(s)``, its signals named as in the fit.

        ``inputs``/``outputs`` are :attr:`input` and :attr:`output`, each ``.`` replaced by
        ``_`` (python-control reserves ``.`` for ``system.signal``: a ULog field
        ``vehicle_local_position.x`` becomes ``vehicle_local_position_x``). The input delay is not
        part of the dynamics (python-control has no delay; no Pade approximation is made): it
        is attached as the attribute ``input_delay`` (s, equal to :attr:`delay`) for reference,
        and any operation on the object (series, feedback, sampling) drops it. Use
        :meth:`to_control` to receive it beside the system, or :meth:`frequency_response`,
        which includes it.
        """
        import control as ct

        sys = ct.tf(self.num, self.den, inputs=[self.input.replace(".", "_")],
                    outputs=[self.output.replace(".", "_")])
        sys.input_delay = self.delay
        return sys

    def to_control(self) -> tuple[ct.TransferFunction, float]:
        """The model as python-control holds it, and its input delay.

        Returns
        -------
        G : control.TransferFunction
            :attr:`model`: ``num(s)/den(s)``, inputs/outputs named after :attr:`input`/:attr:`output`.
        delay : float
            Input delay, s: the model is ``G(s) exp(-delay s)`` (for a delay-free object of
            your own choice, e.g. ``control.pade(delay, n)`` in series, or shift the input
            ``round(delay / ts)`` samples).
        """
        return self.model, self.delay

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of ``theta`` (and ``delay``)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def predict(self, u: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """Simulated output for an input.

        Parameters
        ----------
        u : array_like
            Input samples (sample time :attr:`ts`).
        y : array_like, optional
            Measured output: when given, the initial state (and the trend, when one was
            estimated) is fitted to it (:func:`compare`); else the model starts at rest.

        Returns
        -------
        numpy.ndarray
            The model output, same length as ``u``.
        """
        if y is None:
            return simulate_zoh(self.structure, self.theta, u, self.ts, self.delay)
        return compare(self.structure, self.theta, self.delay, self.ts, u, y, self.trend)

    def score(self, data: FlightData) -> float:
        """Fit % on an experiment (MATLAB ``compare``).

        Parameters
        ----------
        data : FlightData
            The experiment, with signals named as in the fit (:attr:`input`, :attr:`output`).

        Returns
        -------
        float
            :func:`fit_percent` of the predicted output.
        """
        return fit_percent(data[self.output], self.predict(data[self.input], data[self.output]))

    def frequency_response(self, w: np.ndarray) -> np.ndarray:
        """``G(jw)`` including the delay.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response.
        """
        return frequency_response(self.structure, self.theta, self.delay, w)

    def uncertainty(self, w: np.ndarray, k: float = 3.0) -> np.ndarray:
        """Multiplicative uncertainty ``|Delta(jw)|`` (:func:`~ilcdob.uncertainty.multiplicative_bound`).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.
        k : float
            Number of standard deviations.

        Returns
        -------
        numpy.ndarray
            The bound per frequency.
        """
        return multiplicative_bound(self.structure, self.theta, self.covariance, self.delay,
                                    self.delay_estimated, w, k)

    def sample(self, n: int, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Plausible models drawn from ``N(theta, covariance)``.

        Parameters
        ----------
        n : int
            Number of models.
        rng : numpy.random.Generator
            The random generator.

        Returns
        -------
        list of (numpy.ndarray, numpy.ndarray, float)
            ``(num, den, delay)`` per model (a drawn delay below 0 is taken as 0).
        """
        mean = np.concatenate([self.theta, [self.delay]]) if self.delay_estimated else self.theta
        draws = rng.multivariate_normal(mean, self.covariance, size=n, method="svd")
        out = []
        for x in draws:
            th, d = (x[:-1], max(0.0, x[-1])) if self.delay_estimated else (x, self.delay)
            den, num = self.structure.split(th)
            out.append((num, den, float(d)))
        return out

    def identification_spec(self, source: str) -> IdentificationSpec:
        """What a fleet file keeps of the fit (:class:`~ilcdob.specs.IdentificationSpec`): structure,
        parameters, covariance and fits, its Delta set's definition.

        Parameters
        ----------
        source : str
            The flights it was identified from.

        Returns
        -------
        IdentificationSpec
        """
        return IdentificationSpec(self.structure.n_poles, self.structure.n_zeros, self.structure.n_integrators,
                                  tuple(self.theta), tuple(map(tuple, self.covariance)), self.delay_estimated,
                                  self.fit_estimation,
                                  self.fit_validation if self.fit_validation is not None else float("nan"), source)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the ``model.json`` of ``ilcdob identify``)."""
        return {
            "num": [float(v) for v in self.num],
            "den": [float(v) for v in self.den],
            "delay": self.delay,
            "structure": {"poles": self.structure.n_poles, "zeros": self.structure.n_zeros,
                          "integrators": self.structure.n_integrators},
            "parameters": [float(v) for v in self.theta],
            "std": [float(v) for v in self.std],
            "delay_estimated": self.delay_estimated,
            "fit_percent": {"estimation": self.fit_estimation, "validation": self.fit_validation,
                            "validation_from_rest": self.fit_validation_rest},
            "covariance": self.covariance.tolist(),
            "noise_variance": self.sigma2,
            "sample_time": self.ts,
            "residuals": {"whiteness_inside_99": self.whiteness.share_inside,
                          "input_correlation_inside_99": self.input_correlation.share_inside},
            "signals": {"input": self.input, "output": self.output},
            "solver": self.solver,
            "trend": self.trend,
            "file_fits_percent": [float(v) for v in self.file_fits],
            "diagnostics": list(self.diagnostics),
        }

    def __repr__(self) -> str:
        held = "" if self.fit_validation is None else f", held-out {self.fit_validation:.1f} %"
        delay = f" * exp(-{self.delay:.4g} s)" if self.delay else ""
        return (f"<TFEstimate {self.input} -> {self.output}: G(s) = ({_poly(self.num)}) / ({_poly(self.den)})"
                f"{delay}; fit {self.fit_estimation:.1f} %{held}; {self.solver.get('status', 'status unknown')}>")

    def _repr_html_(self) -> str:
        std = np.sqrt(np.clip(np.diag(np.asarray(self.covariance)), 0.0, None))
        names = self.structure.parameter_names + (["delay (s)"] if self.delay_estimated else [])
        values = [*np.asarray(self.theta, float), *([self.delay] if self.delay_estimated else [])]
        rows = [[n, float(v), float(e)] for n, v, e in zip(names, values, std)]
        rows += [["fit estimation (%)", self.fit_estimation, ""],
                 ["fit held-out (%)", "-" if self.fit_validation is None else self.fit_validation, ""],
                 ["solver", self.solver.get("status", "-"), ""]]
        return html_table(f"G(s) = ({_poly(self.num)}) / ({_poly(self.den)})"
                          + (f" exp(-{self.delay:.4g} s)" if self.delay else ""), ["", "value", "1 sigma"], rows)

    def summary(self) -> str:
        """Human-readable summary (parameters with 1-sigma, fit, residual tests)."""
        lines = [f"G(s) = ({_poly(self.num)}) / ({_poly(self.den)})"
                 + (f" * exp(-{self.delay:.4g} s)" if self.delay else "")]
        names = self.structure.parameter_names + (["delay"] if self.delay_estimated else [])
        vals = list(self.theta) + ([self.delay] if self.delay_estimated else [])
        for nme, v, sd in zip(names, vals, self.std):
            lines.append(f"  {nme:>5} = {v: .6g} +- {sd:.3g} (1 sigma)")
        lines.append(f"fit: estimation {self.fit_estimation:.2f} %"
                     + (f", validation {self.fit_validation:.2f} %" if self.fit_validation is not None else "")
                     + (f" ({self.fit_validation_rest:.2f} % from rest)" if self.fit_validation_rest is not None
                        else ""))
        lines.append(f"residuals: whiteness {100 * self.whiteness.share_inside:.0f} % of lags inside the 99 % band, "
                     f"input correlation {100 * self.input_correlation.share_inside:.0f} %")
        lines += [f"note: {d}" for d in self.diagnostics]
        return "\n".join(lines)


#: A delay on its lower bound 0 is noted when moving it below 0 would lower the criterion by at least this many
#: residual variances (first-order prediction; 3.84 is the 95 % point of chi-square with one degree of freedom).
DELAY_BOUND_GAIN = 4.0
#: A file whose own fit is this many points below the median file's is flagged (:func:`fit_diagnostics`).
FILE_FIT_GAP = 20.0
#: Estimation and held-out fits, and held-out fits refitted and from rest, this many points apart are noted.
FIT_GAP = 30.0
#: An estimation fit below this (%) leaves more than half the output's variation unexplained: noted as an axis the
#: log does not identify (too weak an excitation, or the wrong structure).
WEAK_FIT = 50.0


def _gain_spread(est: TFEstimate) -> str:
    """The model's steady-state (or, with integrators, its lowest-order) gain ``b_0 / a_0`` with its 1-sigma
    spread, linearised; "" where ``a_0`` is 0."""
    n = est.structure.n_free_poles
    a0 = float(est.den[n]) if n else 1.0
    if a0 == 0:
        return ""
    b0 = float(est.num[-1])
    g = np.zeros(len(est.theta))
    g[-1] = 1 / a0
    if n:
        g[n - 1] = -b0 / a0 ** 2
    cov = np.asarray(est.covariance, float)[: g.size, : g.size]
    return f"{b0 / a0:.4g} +- {float(np.sqrt(max(g @ cov @ g, 0.0))):.2g} (1 sigma)"
#: A pole pair damped less than this is marginal: a record of finite length cannot tell it from an undamped
#: one or from a sinusoid in the data, and a held-out score that refits the initial state hides it
#: (:func:`unidentified_poles`).
MARGINAL_DAMPING = 0.005


def pole_std(est: TFEstimate) -> tuple[np.ndarray, np.ndarray]:
    """The fit's free poles and their 1-sigma uncertainty, rad/s, from the parameters' covariance, linearised:
    a simple root ``r`` of ``A(s) = s^n + a_{n-1} s^{n-1} + ... + a_0`` moves by
    ``dr = -sum_k r^k da_k / A'(r)``.

    Parameters
    ----------
    est : TFEstimate

    Returns
    -------
    poles : numpy.ndarray
        The roots of ``A`` (complex).
    std : numpy.ndarray
        Their standard deviations (inf at a repeated root, where the linearisation fails).
    """
    n = est.structure.n_free_poles
    a = np.asarray(est.den, float)[: n + 1]
    roots = np.roots(a) if n else np.zeros(0, complex)
    cov = np.asarray(est.covariance, float)[:n, :n]
    da = np.polyder(a)
    out = np.full(roots.size, np.inf)
    for i, r in enumerate(roots):
        slope = np.polyval(da, r)
        if abs(slope) > 1e-12 * max(1.0, abs(r)) ** (n - 1):
            g = -(r ** np.arange(n - 1, -1, -1)) / slope  # theta's a_{n-1} .. a_0
            out[i] = float(np.sqrt(max(np.real(g @ cov @ np.conj(g)), 0.0)))
    return roots, out


def unidentified_poles(est: TFEstimate) -> list[str]:
    """The fit's poles the data cannot show: beyond the Nyquist frequency, pairs damped less than
    :data:`MARGINAL_DAMPING`, or poles whose 1-sigma uncertainty (:func:`pole_std`) exceeds their magnitude (the
    model's integrators are structure, not estimates, and are not listed).

    Parameters
    ----------
    est : TFEstimate

    Returns
    -------
    list of str
        One line per such pole (its value in rad/s and why); empty when every pole is identified.
    """
    roots, std = pole_std(est)
    nyquist = np.pi / est.ts
    out = []
    for k in np.argsort(-np.abs(roots)):
        r = roots[k]
        if r.imag < 0:
            continue
        mag = abs(r)
        if mag > nyquist:
            out.append(f"{r:.4g} rad/s: beyond the Nyquist frequency {nyquist:.4g} rad/s")
        elif r.imag > 0 and -r.real / mag < MARGINAL_DAMPING:
            out.append(f"{r:.4g} rad/s: damping {-r.real / mag:.2g}, below {MARGINAL_DAMPING:g} (marginal)")
        elif np.isfinite(std[k]) and std[k] > mag:
            out.append(f"{r:.4g} rad/s: 1-sigma uncertainty {std[k]:.3g} rad/s exceeds its magnitude (the data "
                       "hardly constrain it)")
    return out


def fit_diagnostics(est: TFEstimate) -> list[str]:
    """What a fit's numbers say beyond its fit %: each an English sentence with its consequence.

    * the estimated delay on a bound of its search: ``max_delay``, or 0 when a negative delay
      would fit significantly better (:data:`DELAY_BOUND_GAIN`, from ``solver["delay_lower_bound_gain"]``);
    * a pole pair damped less than :data:`MARGINAL_DAMPING` (marginal: not identified), or a pole whose
      uncertainty exceeds its magnitude (:func:`unidentified_poles`);
    * an estimation fit below :data:`WEAK_FIT` %: the log does not identify this axis;
    * a pole or zero beyond the Nyquist frequency (the data cannot show it: fewer poles/zeros);
    * residuals not white (the whiteness test fails, fewer than 95 % of the lags inside the 99 % band:
      coloured noise or missing dynamics, and the covariance-based Delta set understates the model error);
    * residuals correlated with the input (the same test on the cross-correlation: missing dynamics);
    * an estimation fit more than :data:`FIT_GAP` points above the held-out fit, or a held-out fit with the
      initial state refitted that far above the same from rest;
    * an estimation file fitting :data:`FILE_FIT_GAP` points or more below the median file;
    * samples left out of the fit as gross errors (``solver["gross_errors"]``, see
      ``FitOptions.outlier_sigmas``), named by file and sample;
    * a start-up transient kept in the fit (``solver["startup_transients"]``);
    * a landed or saturated segment, the input held at its extreme while the output stays still
      (:mod:`.held`): among the gross errors (``held``), or left in the fit (``solver["held_inputs"]``).

    Parameters
    ----------
    est : TFEstimate
        The fit; an estimated delay is checked against ``solver["max_delay"]``, the bound of its search.

    Returns
    -------
    list of str
        Empty when nothing stands out.
    """
    out = []
    if est.delay_estimated:
        gain = est.solver.get("delay_lower_bound_gain", 0.0)
        if est.delay <= 1e-9 and gain >= DELAY_BOUND_GAIN:
            out.append(f"the delay ended on its lower bound 0 s and a negative one would lower the criterion by "
                       f"{gain:.3g} times the residual variance: the output leads the input (a log whose input is "
                       "recorded late, a non-causal filter in the log), or the model lacks the phase lead of a "
                       "zero; check the time stamps of the signals, or fit one zero more")
        elif (max_delay := est.solver.get("max_delay")) is not None and est.delay >= max_delay * (1 - 1e-6):
            out.append(f"the delay ended on its upper bound {max_delay:g} s: raise --max-delay (FitOptions.max_delay)")
    unknown = unidentified_poles(est)
    loose = [p for p in unknown if "uncertainty" in p]
    if loose:
        out.append(f"pole(s) at {'; '.join(loose)}: not identified; try fewer poles or a longer or richer "
                   "excitation")
    if est.fit_estimation < WEAK_FIT:
        gain = _gain_spread(est)
        out.append(f"the model explains little of the output (estimation fit {est.fit_estimation:.1f} %, below "
                   f"{WEAK_FIT:g} %): the input moves this output weakly against noise and disturbances, or the "
                   "structure misses its dynamics; such a fit is not an identification"
                   + (f" (its gain is {gain})" if gain else "") + "; excite the axis more (a larger or longer "
                   "chirp or steps) or check the signals")
    marginal = [p for p in unknown if "marginal" in p]
    if marginal:
        out.append(f"pole pair(s) at {'; '.join(marginal)}: not identified (a mode this lightly damped, or a "
                   "sinusoid in the data, fits from a refitted initial state but not from rest); try fewer "
                   "poles or check the log for a periodic disturbance")
    nyquist = np.pi / est.ts
    for what, poly in (("pole", est.den), ("zero", est.num)):
        roots = np.roots(poly) if np.size(poly) > 1 else np.zeros(0)
        far = roots[np.abs(roots) > nyquist]
        if far.size:
            out.append(f"{what}(s) at {', '.join(f'{r:.4g}' for r in far)} rad/s lie beyond the Nyquist frequency "
                       f"{nyquist:.4g} rad/s: the data cannot show them; try fewer {what}s")
    if not est.whiteness.passed:
        out.append(f"the residuals are not white ({100 * est.whiteness.share_inside:.0f} % of lags inside the 99 % "
                   "band, the test needs 95 %): coloured noise or missing dynamics; the Delta set from the covariance "
                   "then understates the model error (state a bound, fleet `uncertainty`)")
    if not est.input_correlation.passed:
        out.append(f"the residuals correlate with the input ({100 * est.input_correlation.share_inside:.0f} % of "
                   "lags inside the 99 % band, the test needs 95 %): dynamics the structure misses; compare other "
                   "orders")
    if est.fit_validation is not None and est.fit_estimation - est.fit_validation > FIT_GAP:
        out.append(f"the estimation fit {est.fit_estimation:.1f} % is far above the held-out fit "
                   f"{est.fit_validation:.1f} %: the model follows the estimation data's noise or disturbances "
                   "(fewer poles or zeros), or the held-out data come from other conditions")
    if est.fit_validation is not None and est.fit_validation_rest is not None and \
            est.fit_validation - est.fit_validation_rest > FIT_GAP:
        out.append(f"the held-out fit is {est.fit_validation:.1f} % with the initial state refitted but "
                   f"{est.fit_validation_rest:.1f} % from rest: the free response carries the score (a marginal or "
                   "very slow mode), or the held-out data do not start at rest")
    for d in est.solver.get("gross_errors", []):
        if "held" in d:
            out.append(_held_note(d, d["held"], est.ts, "were left out of the fit, the record cut there (keep them "
                                  "with --keep-outliers, FitOptions(outlier_sigmas=None))"))
            continue
        out.append(f"{d['samples']} samples of {d['source']} (samples {d['first']}-{d['last']}) lay far off the "
                   "model (gross errors: a glitch or corrupt samples in the log) and were left out of the fit, the "
                   "record cut there; check that file, or keep them with --keep-outliers "
                   "(FitOptions(outlier_sigmas=None))")
    for d in est.solver.get("startup_transients", []):
        out.append(f"the first {d['samples']} samples of {d['source']} lie far off the model but move smoothly: a "
                   "start-up transient (the vehicle not at rest when the log starts, or dynamics of the start the "
                   "structure lacks), not a glitch; kept in the fit: cut them from the log if they are not the "
                   "system's response to the input")
    for d in est.solver.get("held_inputs", []):
        out.append(_held_note(d, d, est.ts, "are kept in the fit and bias it: fit the flight without them "
                                  "(--start/--stop, --segment)"))
    if len(est.file_fits) >= 3:
        median = float(np.median(est.file_fits))
        for i, f in enumerate(est.file_fits):
            if f < median - FILE_FIT_GAP:
                out.append(f"estimation file {i + 1} fits {f:.1f} %, the median file {median:.1f} %: check it for "
                           "corrupt samples, a different configuration or a wrong signal")
    return out


def _held_note(where: dict, held: dict, ts: float, fate: str) -> str:
    """The note of a held-input segment (:mod:`.held`): where, the held value, and what was done with it."""
    t0, t1 = time_text(where["first"] * ts), time_text(where["last"] * ts)
    return (f"samples {where['first']}-{where['last']} of {where['source']} (t = {t0} to {t1} s from its "
            f"start): the input is held at {held['value']:.6g} (its {held['extreme']}) while the output does not "
            f"follow: a landed or saturated segment (the vehicle on the ground, a setpoint at its limit), not a "
            f"glitch; these samples {fate}")


def trend_basis(n: int, degree: int) -> np.ndarray:
    """Basis of a polynomial output trend: Legendre polynomials over the record.

    Parameters
    ----------
    n : int
        Number of samples.
    degree : int
        Highest degree.

    Returns
    -------
    numpy.ndarray
        ``n x (degree + 1)``, columns of degree 0..``degree`` on ``[-1, 1]``.
    """
    return np.polynomial.legendre.legvander(np.linspace(-1.0, 1.0, n), degree)


def compare(structure: ModelStructure, theta: np.ndarray, delay: float, ts: float, u: np.ndarray, y: np.ndarray,
            trend: int | None = None, initial_state: bool = True) -> np.ndarray:
    """Simulated output with the initial state (and a trend) chosen by least squares (MATLAB ``compare``).

    Parameters
    ----------
    structure : ModelStructure
        The model's orders.
    theta : numpy.ndarray
        Its parameters.
    delay : float
        Input delay, s.
    ts : float
        Sample time, s.
    u : numpy.ndarray
        Input samples.
    y : numpy.ndarray
        Measured output, same length.
    trend : int, optional
        Degree of a polynomial output trend fitted too (None: none).
    initial_state : bool
        Fit the initial state (default); False: the model starts at rest, only the trend is fitted (the
        held-out score from rest of :class:`TFEstimate`).

    Returns
    -------
    numpy.ndarray
        The model output closest to ``y`` over initial states (and trends).
    """
    forced = simulate_zoh(structure, theta, u, ts, delay)
    basis = free_response_basis(structure, theta, ts, u.size) if initial_state else np.zeros((u.size, 0))
    if trend is not None:
        basis = np.column_stack([basis, trend_basis(u.size, trend)])
    if basis.shape[1] == 0:
        return forced
    scale = np.linalg.norm(basis, axis=0)
    scale[scale == 0] = 1.0
    x0, *_ = np.linalg.lstsq(basis / scale, y - forced, rcond=None)
    return forced + (basis / scale) @ x0
