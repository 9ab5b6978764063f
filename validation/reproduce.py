"""Reproduce the paper's validation: no DOB, only DOB, and learning passed around the fleet.

Learning chain (cyclic, paper Sec. IV): every system first flies without DOB and with DOB
only. The first system of the order flies the DOB-only trial that starts the chain; then
each flight learns from the flight before it in the chain::

    order = [A, B, C]:  B <- A(DOB only), C <- B, A <- C, B <- A, C <- B, A <- C, ...

until every system has flown ``iterations`` learning trials; ``rmse_learning[i]`` is a
system's (i+1)-th learning trial. Each learning signal comes from the learning law ``law``
(:mod:`ilcdob.design.law.laws`), always built from the systems' *models*:

* ``"paper"`` (default): the closed-form filters of the Theorem (paper Sec. III,
  :func:`ilcdob.design.closed_form_filters`) on the previous flight;
* ``"exact-reference"``: the same filters with the reference term ``(1 - G_r) r`` kept
  (:mod:`ilcdob.design.maps.reference`), from the scenario's reference and its acceleration;
* ``"multi-source"``: from the latest flight of every system that has flown in the chain so
  far (the first system's DOB-only trial included), confidence-weighted by each system's
  Delta set (identification or fleet ``uncertainty`` bound, 8 samples, seed 0; systems with
  neither count as exact models) (:mod:`ilcdob.design.law.multi_source`).

With one earlier flight (each scenario's first learning flight) ``multi-source`` is the
paper's law; with a hover (no reference motion) ``exact-reference`` is.

Every learning signal is what ``ilcdob design`` computes from the previous flight
(:meth:`ilcdob.design.pair.PairDesign.learning`): the law through the learning band chosen
from that flight's measured error (:mod:`ilcdob.design.filters.band`; ``bandwidth``), bounded by the
learning vehicle's acceleration limit (fleet ``limits``). With ``sensor_noise_std > 0`` every
flight measures its position with white noise (seeded per scenario, system and flight) and
learns from its measured error; the RMSE is that of the true error. Without noise and with
trusted models the band is off and the law is the Theorem's filters as they are.

The report of a reproduction is :meth:`ReproductionResult.files`: ``results.json``, the
figures (:mod:`ilcdob.validation.figures`) and a ``README.md`` (:func:`markdown_index`), as
content to be written by the caller.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Callable, Mapping

import numpy as np

from ilcdob.design import LearningFilters, closed_form_filters
from ilcdob.design.sets.delta import DeltaSet, delta_set
from ilcdob.design.law.laws import DEFAULT_LAW, LAW_DESCRIPTIONS, check_law, law_for
from ilcdob.design.law.multi_source import SourceTrial, multi_source_learning
from ilcdob.design.pair import PairDesign, design_pair
from ilcdob.errors import SpecError
from ilcdob.specs import check_noise_std
from ilcdob.fleet import Fleet
from ilcdob.signals import check_grid
from ilcdob.display import html_table

from .scenarios import Scenario, check_order, scenario
from .simulate import Flight, simulate_flight

__all__ = ["SystemResult", "ScenarioResult", "ReproductionResult", "check_iterations", "check_flights_memory",
           "learning_chain", "law_delta_sets", "pair_designs", "run_scenario", "reproduce", "markdown_index",
           "json_document", "FIGURE_TEXT", "FLIGHT_ARRAYS", "MAX_FLIGHTS_BYTES"]

#: Arrays of samples one flight holds (:class:`~ilcdob.validation.simulate.Flight`: t, r, y, e, d, d_hat,
#: d_f, u2, y_meas, e_meas; a nonlinear flight one more, d_est).
FLIGHT_ARRAYS = 10

#: Most memory the flights of one reproduction may hold, bytes: every flight is kept for the report. The
#: largest run ilcdob is built for, the four scenarios (220 s) at 1 ms, three systems, 100 iterations
#: (``reproduce``'s most: 102 flights a system), holds 220,000 x 3 x 102 x 10 x 8 bytes = 5.4 GB; the
#: paper's run at 20 ms and 3 iterations, 13 MB.
MAX_FLIGHTS_BYTES = 8e9

#: Caption of each figure in the report's README.md (``error_s<N>`` and ``disturbance_s<N>``
#: are captioned per scenario by :func:`markdown_index`).
FIGURE_TEXT = {
    "rmse_bars.png": "Tracking RMSE per scenario and system (log scale): no DOB, only DOB, learning iterations.",
    "bode_loops.png": "Bode plots of G_r and G_d of every system (dotted: G_d without DOB).",
    "identified_models.png": "Identified plant models with their 3-sigma multiplicative uncertainty band "
                             "(from the parameter covariance of the fit).",
    "bode_learning.png": "Bode plots of the learning filters L1 and L2 of every pair flown (with equal "
                         "Q filters L2 = (1 - Q_j)/(1 - Q_{j-1}) = 1 exactly).",
    "bode_te.png": "Te1, Te2 (error propagation with learning when every true plant is 10 % stronger "
                   "than its model; with exact models both vanish) and Omega (disturbance -> DOB estimate).",
}


@dataclass(frozen=True)
class SystemResult:
    """Flights of one system in one scenario.

    Attributes
    ----------
    no_dob : Flight
        The flight without DOB.
    dob : Flight
        The flight with the DOB only.
    learning : tuple of Flight
        The learning flights, in chain order.
    """

    no_dob: Flight
    dob: Flight
    learning: tuple[Flight, ...]

    def metrics(self) -> dict[str, object]:
        """RMSE figures for results.json (m, and m/s^2 for ``rmse_dhat_*`` and ``peak_d_f_learning``)."""
        return {
            "rmse_no_dob": self.no_dob.rmse,
            "rmse_dob": self.dob.rmse,
            "rmse_learning": [f.rmse for f in self.learning],
            "rmse_dhat_dob": self.dob.rmse_dhat,
            "rmse_dhat_learning": [f.rmse_dhat for f in self.learning],
            "peak_d_f_learning": [float(np.max(np.abs(f.d_f))) for f in self.learning],
        }


@dataclass(frozen=True)
class ScenarioResult:
    """All flights of one scenario.

    Attributes
    ----------
    scenario : Scenario
    order : list of str
        The scenario's learning order of the systems.
    systems : dict of str to SystemResult
        Flights per system.
    chain : list of (str, str)
        (source, target) of each learning flight, in the order flown.
    """

    scenario: Scenario
    order: list[str]
    systems: dict[str, SystemResult]
    chain: list[tuple[str, str]] = field(default_factory=list)

    def to_dict(self) -> dict[str, object]:
        """The scenario's entry of ``results.json`` (RMSE in m, and m/s^2 for ``rmse_dhat_*``)."""
        return {
            "id": self.scenario.id,
            "title": self.scenario.title,
            "duration_s": self.scenario.duration,
            "order": self.order,
            "chain": [list(p) for p in self.chain],
            "systems": {name: self.systems[name].metrics() for name in self.order},
        }


@dataclass(frozen=True)
class ReproductionResult:
    """Every scenario run, plus the fleet, the filters used and the learning law.

    Subclasses (the nonlinear reproduction, :mod:`ilcdob.validation.nonlinear`) change the
    report through :meth:`to_dict` (``results.json``) and :meth:`markdown_plant` (the
    description at the top of ``README.md``).

    Attributes
    ----------
    fleet : Fleet
        The fleet flown (its models).
    scenarios : list of ScenarioResult
        One per scenario, in the order run.
    iterations : int
        Learning trials per system.
    filters : dict of (str, str) to LearningFilters
        The Theorem's pair (L1, L2) of every pair flown with the ``paper`` or
        ``exact-reference`` law; empty for ``multi-source`` (no single pair's filters).
    elapsed_s : float
        Run time of the simulations, s.
    law : str
        The learning law (:mod:`ilcdob.design.law.laws`).
    sensor_noise_std : float
        Position-sensor noise of every flight, m (0: exact sensors).
    bandwidth : "auto", float or None
        The learning band asked for (:mod:`ilcdob.design.filters.band`).
    identified_toml : str
        The fleet file of models identified by the run (TOML text, written as
        ``identified_fleet.toml``); empty when the models were given.
    """

    fleet: Fleet
    scenarios: list[ScenarioResult]
    iterations: int
    filters: dict[tuple[str, str], LearningFilters]
    elapsed_s: float
    law: str = DEFAULT_LAW
    sensor_noise_std: float = 0.0
    bandwidth: object = "auto"
    identified_toml: str = ""

    def _ratios(self) -> list[tuple[int, str, dict[str, float]]]:
        return [(sr.scenario.id, name, sr.systems[name].metrics()) for sr in self.scenarios for name in sr.order]

    def __repr__(self) -> str:
        worst = max((m["rmse_learning"][-1] / m["rmse_dob"] for _, _, m in self._ratios()), default=float("nan"))
        return (f"<{type(self).__name__} law {self.law}, {len(self.scenarios)} scenario(s) x "
                f"{len(self.fleet.systems)} systems, {self.iterations} iteration(s); last learning / DOB-only RMSE "
                f"at most {100 * worst:.3g} %>")

    def _repr_html_(self) -> str:
        rows = [[sid, name, 1e3 * m["rmse_no_dob"], 1e3 * m["rmse_dob"], *(1e3 * v for v in m["rmse_learning"])]
                for sid, name, m in self._ratios()]
        return html_table(f"Tracking RMSE in mm (law {self.law})",
                          ["scenario", "system", "no DOB", "DOB only",
                           *(f"learning {i + 1}" for i in range(self.iterations))], rows)

    def to_dict(self) -> dict[str, object]:
        """The content of ``results.json`` (RMSE in m, and m/s^2 for ``rmse_dhat_*``)."""
        return {
            "plant": "linear",
            "law": self.law,
            "fleet": self.fleet.source,
            "sample_time": self.fleet.sample_time,
            "iterations": self.iterations,
            "sensor_noise_std_m": self.sensor_noise_std,
            "bandwidth": self.bandwidth,
            "units": {"rmse": "m", "rmse_dhat": "m/s^2", "peak_d_f": "m/s^2"},
            "scenarios": [s.to_dict() for s in self.scenarios],
        }

    def markdown_plant(self) -> list[str]:
        """The description of the run at the top of ``README.md``, as Markdown lines."""
        return [
            f"Fleet: `{PurePath(self.fleet.source).name}` ({', '.join(self.fleet.names)}), sample time "
            f"{self.fleet.sample_time} s, exact models (Case I of the Theorem: each simulated plant is its "
            f"model), "
            + (f"{1e3 * self.sensor_noise_std:g} mm of white position-sensor noise, " if self.sensor_noise_std else "")
            + f"{self.iterations} learning "
            "iterations. Regenerate with `ilcdob reproduce"
            + ("" if self.law == "paper" else f" --law {self.law}")
            + " --out <dir>`; numbers are in `results.json`."]

    def files(self, figures: Mapping[str, object] | None = None) -> dict[str, object]:
        """The report of the reproduction: file name -> content.

        A result does not draw itself: the caller draws the figures
        (:func:`ilcdob.validation.figures.reproduction_figures`, which reads this result) and
        passes them here, so that the result's module needs no plotting.

        Parameters
        ----------
        figures : mapping of str to object, optional
            The figures by file name (``matplotlib.figure.Figure``, or ``PendingFigure`` for
            :func:`~ilcdob.validation.figures.render_figures`); README.md shows them in this order.

        Returns
        -------
        dict of str to object
            The figures, then ``README.md``
            (str, :func:`markdown_index`), ``identified_fleet.toml`` when the run identified its
            models (:attr:`identified_toml`), then ``results.json`` (a JSON document,
            :meth:`to_dict` with non-finite numbers as null). ``results.json`` comes last: written
            in this order, its presence means the files beside it are complete.
        """
        out: dict[str, object] = dict(figures or {})
        out["README.md"] = markdown_index(self, list(out))
        if self.identified_toml:
            out["identified_fleet.toml"] = self.identified_toml
        out["results.json"] = json_document(self.to_dict())
        return out


def json_document(data: object) -> object:
    """``data`` as standard JSON content: every non-finite float replaced by None.

    Parameters
    ----------
    data : object
        Nested dicts, lists and tuples (tuples become lists) of JSON values; floats may be
        NaN or infinite (numpy floats and integers are converted to Python numbers).

    Returns
    -------
    object
        The same structure, with ``None`` where a number was not finite.
    """
    if isinstance(data, dict):
        return {k: json_document(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [json_document(v) for v in data]
    if isinstance(data, (bool, np.bool_)):
        return bool(data)
    if isinstance(data, np.integer):
        return int(data)
    if isinstance(data, (float, np.floating)):
        return float(data) if np.isfinite(data) else None
    return data


def markdown_index(res: ReproductionResult, figures: list[str]) -> str:
    """The ``README.md`` of a reproduction report: description, RMSE table, fits, figures.

    Parameters
    ----------
    res : ReproductionResult
        The reproduction; its :meth:`~ReproductionResult.markdown_plant` opens the text.
    figures : list of str
        File names of the figures shown, in order (captions from :data:`FIGURE_TEXT`).

    Returns
    -------
    str
        The Markdown text.
    """
    lines = [
        "# Reproduction of Modi et al. (2024), Section IV",
        "",
        *res.markdown_plant(),
        "",
        f"Learning law: **{res.law}**, {LAW_DESCRIPTIONS[res.law]} (`ilcdob.design.law.laws`; choose with `--law`).",
        "",
        "Tracking RMSE in mm (no DOB / only DOB / learning 1..n) and RMSE of the total disturbance "
        "estimate d_hat + d_f against the true disturbance in m/s^2 (only DOB / learning 1):",
        "",
        "| scenario | system | no DOB | only DOB | " + " | ".join(
            f"learning {i + 1}" for i in range(res.iterations)) + " | learning 1 / DOB | d est. DOB | d est. learning 1 |",
        "|---|---|---|---|" + "---|" * res.iterations + "---|---|---|",
    ]
    for sr in res.scenarios:
        for name in sr.order:
            m = sr.systems[name].metrics()
            learn = " | ".join(f"{1e3 * v:.3f}" for v in m["rmse_learning"])
            lines.append(
                f"| {sr.scenario.id} | {name} | {1e3 * m['rmse_no_dob']:.1f} | {1e3 * m['rmse_dob']:.1f} | "
                f"{learn} | {m['rmse_learning'][0] / m['rmse_dob']:.4f} | {m['rmse_dhat_dob']:.3f} | "
                f"{m['rmse_dhat_learning'][0]:.3f} |")
    idents = [(s.name, s.identification, s.nominal_plant) for s in res.fleet.systems if s.identification]
    if idents:
        lines += ["", "## Identified plant models", "",
                  "Identified from synthetic step and chirp flights of the nonlinear vehicles "
                  "(`ilcdob identify-fleet`); fit in % (MATLAB definition) on estimation and held-out flights, "
                  "1-sigma parameter uncertainty from the fit's covariance.", "",
                  "| system | model P(s) | parameters (1 sigma) | fit estimation | fit validation |",
                  "|---|---|---|---|---|"]
        for name, ident, plant in idents:
            sd = np.sqrt(np.diag(np.asarray(ident.covariance)))
            pars = ", ".join(f"{v:.4g} +- {e:.2g}" for v, e in zip(ident.parameters, sd))
            model = f"({' '.join(f'{v:.4g}' for v in plant.num)}) / ({' '.join(f'{v:.4g}' for v in plant.den)})"
            lines.append(f"| {name} | {model} | {pars} | {ident.fit_estimation:.2f} % | {ident.fit_validation:.2f} % |")
    lines += ["", f"Run time {res.elapsed_s:.1f} s for the simulations.", "", "## Figures", ""]
    for fig in figures:
        text = FIGURE_TEXT.get(fig)
        if text is None and fig.startswith("error_s"):
            text = (f"Scenario {fig[7:-4]}: tracking error (m) against time of every system: no DOB, DOB only "
                    "and every learning iteration (left), the learning iterations alone (right).")
        elif text is None and fig.startswith("disturbance_s"):
            text = (f"Scenario {fig[13:-4]}: disturbance estimate (m/s^2) of every system against the true "
                    "disturbance: DOB only and d_hat + d_f of every learning iteration (left), their errors (right).")
        lines += [f"{text}", "", f"![{fig}]({fig})", ""]
    return "\n".join(lines)


def _filters_for(fleet: Fleet, cache: dict, src: str, tgt: str) -> LearningFilters:
    if (src, tgt) not in cache:
        cache[(src, tgt)] = closed_form_filters(fleet.loop(src), fleet.loop(tgt))
    return cache[(src, tgt)]


def check_iterations(iterations: object) -> int:
    """``iterations`` if it is a number of learning iterations (an integer >= 1), else :class:`SpecError`.

    Parameters
    ----------
    iterations : object
        The value given.

    Returns
    -------
    int
    """
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise SpecError(f"`iterations`: got {iterations!r}, expected an integer >= 1")
    return iterations


def check_flights_memory(ts: float, scenarios: list[Scenario], systems: int, iterations: int,
                         arrays: int = FLIGHT_ARRAYS) -> None:
    """Check, before anything is flown, that the flights of a run fit :data:`MAX_FLIGHTS_BYTES`.

    Each scenario's grid is checked first (:func:`ilcdob.signals.check_grid`); then ``systems``
    systems fly every scenario ``iterations + 2`` times (no DOB, DOB only, the learning
    iterations), each flight ``arrays`` arrays of 8-byte samples.

    Parameters
    ----------
    ts : float
        Sample time, s.
    scenarios : list of Scenario
        The scenarios flown.
    systems : int
        Systems flown in each.
    iterations : int
        Learning iterations.
    arrays : int
        Arrays of samples a flight holds (:data:`FLIGHT_ARRAYS`).

    Raises
    ------
    SpecError
        A scenario of more than :data:`ilcdob.signals.MAX_GRID_SAMPLES` samples, or flights of more
        than :data:`MAX_FLIGHTS_BYTES` (the message names the sample time, the durations, the
        counts and the bound).
    """
    for sc in scenarios:
        check_grid(sc.duration, ts, f"scenario {sc.id} ({sc.title})")
    seconds = sum(sc.duration for sc in scenarios)
    samples = seconds / ts
    size = samples * systems * (iterations + 2) * arrays * 8.0
    if size > MAX_FLIGHTS_BYTES:
        raise SpecError(f"the flights of {len(scenarios)} scenario(s), {seconds:g} s at a sample time of {ts:g} s "
                        f"({samples:.4g} samples), {systems} systems, {iterations + 2} flights each (no DOB, DOB "
                        f"only, {iterations} learning), {arrays} arrays of 8-byte samples a flight: {size / 1e9:.3g} "
                        f"GB, all kept for the report; expected at most {MAX_FLIGHTS_BYTES / 1e9:g} GB: fly fewer "
                        "iterations or scenarios, or at a longer sample time")


def learning_chain(order: list[str], iterations: int, first: Flight,
                   step: Callable[[str, str, Flight], Flight]) -> tuple[dict[str, list[Flight]], list[tuple[str, str]]]:
    """Pass learning around ``order`` cyclically (module docstring), starting from ``first``.

    Parameters
    ----------
    order : list of str
        The systems in learning order.
    iterations : int
        Learning flights per system.
    first : Flight
        The flight that starts the chain (the first system's DOB-only trial).
    step : callable
        ``step(source, target, previous_flight)`` designs the target's learning signal from
        the previous flight and flies it; returns the new flight.

    Returns
    -------
    learning : dict of str to list of Flight
        Each system's learning flights, in order.
    chain : list of (str, str)
        (source, target) of every step.
    """
    learning: dict[str, list[Flight]] = {name: [] for name in order}
    chain = []
    prev = first
    n = len(order)
    for k in range(iterations * n):
        src, tgt = order[k % n], order[(k + 1) % n]
        if n == 1:
            src = tgt = order[0]
        prev = step(src, tgt, prev)
        learning[tgt].append(prev)
        chain.append((src, tgt))
    return learning, chain


def pair_designs(fleet: Fleet, filters: dict, law: str, r: np.ndarray, a_ref: np.ndarray,
                 bandwidth: object = "auto", disturbance: str = "command") -> Callable[[str, str], PairDesign]:
    """``design(source, target)``: the closed-form design a learning flight of a chain flies, as
    ``ilcdob design --trial`` makes it (:func:`ilcdob.design.pair.design_pair`), built once per pair.

    Pairs learning with the ``paper`` or ``exact-reference`` law also enter ``filters`` (their
    Theorem filters, for the figures); ``multi-source`` uses the pair's band, limit and paper-law
    filters around its own learning.

    Parameters
    ----------
    fleet : Fleet
    filters : dict
        Cache of closed-form filters per (source, target), filled as pairs are designed.
    law : str
        Learning law (:mod:`ilcdob.design.law.laws`).
    r, a_ref : numpy.ndarray
        The scenario's reference (m) and its acceleration (m/s^2), for ``exact-reference``.
    bandwidth : "auto", float or None
        The learning band.
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts (:mod:`ilcdob.design.maps.flown`).

    Returns
    -------
    callable
        ``design(source, target) -> PairDesign``.
    """
    designs: dict[tuple[str, str], PairDesign] = {}

    def design(src: str, tgt: str) -> PairDesign:
        if (src, tgt) not in designs:
            if law != "multi-source":
                _filters_for(fleet, filters, src, tgt)
            designs[(src, tgt)] = design_pair(fleet, src, tgt, "closed-form", band=bandwidth,
                                              law=DEFAULT_LAW if law == "multi-source" else law_for(law, r, a_ref),
                                              disturbance=disturbance)
        return designs[(src, tgt)]

    return design


def law_delta_sets(fleet: Fleet, k: int = 8, seed: int = 0) -> dict[str, DeltaSet]:
    """Delta sets of the ``multi-source`` law: every system with an identification or a fleet bound.

    Systems with neither are left out (their models count as exact: the error-power floor).

    Parameters
    ----------
    fleet : Fleet
        The fleet.
    k : int
        Samples per Delta set.
    seed : int
        Seed of the draw (one generator for the whole fleet, in fleet order).
    """
    rng = np.random.default_rng(seed)
    return {s.name: delta_set(s, fleet.sample_time, k, rng) for s in fleet.systems
            if s.identification is not None or s.uncertainty is not None}


def run_scenario(fleet: Fleet, sc: Scenario, iterations: int = 3,
                 filters: dict | None = None, law: str = DEFAULT_LAW,
                 deltas: dict[str, DeltaSet] | None = None, sensor_noise_std: float = 0.0, seed: int = 0,
                 bandwidth: object = "auto", order: list[str] | None = None) -> ScenarioResult:
    """Fly one scenario for every system: no DOB, only DOB, ``iterations`` learning trials.

    Parameters
    ----------
    fleet : Fleet
    sc : Scenario
    iterations : int
        Learning trials per system (>= 1).
    filters : dict, optional
        Cache of closed-form filters per (source, target), filled as pairs are flown.
    law : {"paper", "exact-reference", "multi-source"}
        Learning law (module docstring, :mod:`ilcdob.design.law.laws`).
    deltas : dict name -> DeltaSet, optional
        ``multi-source``: the confidence weights' Delta sets (default :func:`law_delta_sets`).
    sensor_noise_std : float
        White position-sensor noise of every flight, m (module docstring).
    seed : int
        Seed of the sensor noise.
    bandwidth : "auto", float or None
        The learning band (:func:`ilcdob.design.pair.design_pair`).
    order : list of str, optional
        Learning order by system name (:func:`~ilcdob.validation.scenarios.check_order`);
        None (default): the scenario's (:meth:`Scenario.order`).

    Raises
    ------
    SpecError
        ``iterations``, ``law``, ``sensor_noise_std`` or ``order`` invalid.
    """
    check_iterations(iterations)
    law = check_law(law)
    noise_std = check_noise_std(sensor_noise_std, "sensor_noise_std")
    filters = {} if filters is None else filters
    ts = fleet.sample_time
    check_flights_memory(ts, [sc], len(fleet.names if order is None else order), iterations)
    t = sc.time(ts)
    r = sc.reference(t)
    a_ref = sc.acceleration(t)
    wind = sc.disturbance(t)
    order = sc.order(fleet.names) if order is None else check_order(fleet.names, order)
    specs = {s.name: s for s in fleet.systems}
    dist = {name: wind + specs[name].noise(t) for name in order}
    index = {name: i for i, name in enumerate(fleet.names)}
    trials = {name: 0 for name in order}

    def fly(name: str, mode: str, d_f: np.ndarray | None = None) -> Flight:
        noise = None
        if noise_std > 0:
            rng = np.random.default_rng(np.random.SeedSequence([int(seed), 2000 + sc.id, index[name], trials[name]]))
            noise = rng.normal(0.0, noise_std, t.size)
        trials[name] += 1
        return simulate_flight(fleet.loop(name), r, dist[name], d_f=d_f, mode=mode, a_ref=a_ref, sensor_noise=noise)

    base = {name: (fly(name, "no_dob"), fly(name, "dob")) for name in order}
    latest: dict[str, Flight] = {order[0]: base[order[0]][1]}  # multi-source: each system's last trial
    if law == "multi-source" and deltas is None:
        deltas = law_delta_sets(fleet)
    pair_design = pair_designs(fleet, filters, law, r, a_ref, bandwidth)
    powers: dict = {}  # multi-source: error powers of the Delta sets, computed once per system

    def step(src: str, tgt: str, prev: Flight) -> Flight:
        design = pair_design(src, tgt)
        if law == "multi-source":
            names = list(latest)
            band = design.band_for(prev.measured_error, prev.d_f)

            def learn(*signals: np.ndarray) -> np.ndarray:
                srcs = [SourceTrial(fleet.loop(nm), signals[2 * i], signals[2 * i + 1], deltas.get(nm))
                        for i, nm in enumerate(names)]
                return multi_source_learning(fleet.loop(tgt), srcs, power_cache=powers)

            signals = [x for nm in names for x in (latest[nm].measured_error, latest[nm].d_f)]
            df = design.learning_law(band, learn=learn).run(signals)
        else:
            df = design.learning(prev.measured_error, prev.d_f).d_f
        flight = fly(tgt, "dob", df)
        latest[tgt] = flight
        return flight

    learning, chain = learning_chain(order, iterations, base[order[0]][1], step)
    systems = {name: SystemResult(base[name][0], base[name][1], tuple(learning[name]))
               for name in order}
    return ScenarioResult(scenario=sc, order=order, systems=systems, chain=chain)


def reproduce(fleet: Fleet, scenario_ids: list[int] = (1, 2, 3, 4), iterations: int = 3,
              progress: Callable[[int, int, str], None] | None = None, law: str = DEFAULT_LAW,
              sensor_noise_std: float = 0.0, seed: int = 0, bandwidth: object = "auto",
              order: list[str] | None = None,
              on_scenario: Callable[[ScenarioResult], None] | None = None) -> ReproductionResult:
    """Run the listed scenarios on ``fleet`` (see module docstring).

    Parameters
    ----------
    fleet : Fleet
        The fleet; its systems' models are the simulated plants (Case I of the Theorem).
    scenario_ids : list of int
        Scenarios 1-4 (:mod:`ilcdob.validation.scenarios`).
    iterations : int
        Learning trials per system (>= 1).
    progress : callable, optional
        Called as ``progress(done, total, what)`` after each scenario: scenarios done, of
        ``total``, and a line saying which one finished and its run time. None: silent.
    law : {"paper", "exact-reference", "multi-source"}
        Learning law (module docstring); recorded in the result.
    sensor_noise_std : float
        White position-sensor noise of every flight, m (0: exact sensors).
    seed : int
        Seed of the sensor noise.
    bandwidth : "auto", float or None
        The learning band (:func:`ilcdob.design.pair.design_pair`).
    order : list of str, optional
        Learning order by system name, flown in every scenario
        (:func:`~ilcdob.validation.scenarios.check_order`); None (default): each scenario's.
    on_scenario : callable, optional
        Called with each scenario's :class:`ScenarioResult` as soon as it is flown, before the
        next (e.g. to start rendering its figures, :func:`ilcdob.validation.figures.scenario_figures`).

    Returns
    -------
    ReproductionResult
        Every flight; :meth:`ReproductionResult.files` makes its report.

    Raises
    ------
    SpecError
        Bad scenario id, ``iterations``, ``law`` or ``order``.
    FleetError
        A system on its own controller (:meth:`~ilcdob.fleet.Fleet.require_paper_loops`).
    """
    fleet.require_paper_loops("reproduce")
    law = check_law(law)
    order = None if order is None else check_order(fleet.names, order)
    noise_std = check_noise_std(sensor_noise_std, "sensor_noise_std")
    check_flights_memory(fleet.sample_time, [scenario(sid) for sid in scenario_ids],
                         len(fleet.names if order is None else order), check_iterations(iterations))
    start = time.perf_counter()
    filters: dict = {}
    deltas = law_delta_sets(fleet) if law == "multi-source" else None
    results = []
    for i, sid in enumerate(scenario_ids, 1):
        sc = scenario(sid)
        t0 = time.perf_counter()
        results.append(run_scenario(fleet, sc, iterations, filters, law, deltas, noise_std, seed, bandwidth, order))
        if on_scenario is not None:
            on_scenario(results[-1])
        if progress is not None:
            progress(i, len(scenario_ids), f"scenario {sid} ({sc.title}, law {law}): "
                                           f"{time.perf_counter() - t0:.1f} s")
    return ReproductionResult(fleet=fleet, scenarios=results, iterations=iterations,
                              filters=filters, elapsed_s=time.perf_counter() - start, law=law,
                              sensor_noise_std=noise_std, bandwidth=bandwidth)
