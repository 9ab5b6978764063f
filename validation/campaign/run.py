"""Running a campaign: sampling the true plants, the workers' state, the Dask client, :func:`run_campaign`."""

from __future__ import annotations

import threading
import time
import warnings
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ilcdob.design.sets.delta import DeltaSet, delta_set
from ilcdob.design.law.laws import DEFAULT_LAW
from ilcdob.design.methods import METHODS, MethodSettings
from ilcdob.design.pair import PairDesign, design_pair, with_law
from ilcdob.design.methods.robust_set import RobustSetOptions
from ilcdob.errors import IlcdobError
from ilcdob.fleet import Fleet
from ilcdob.loop import LoopSystem

from ..compare import PairScenario, evaluate_case, pair_scenario
from .cluster import WORKERS_PER_CORE, Cluster, cluster_client
from .options import CampaignError, CampaignOptions, campaign_settings
from .statistics import CPU_S, CampaignResult, campaign_statistics
from .store import SAMPLES_FILE, SampleStore, campaign_lock, check_settings

__all__ = ["CPU_S", "FIR_DESIGN_SAMPLES", "WORKERS_PER_CORE", "draw_true_loops", "run_sample", "run_campaign"]

#: Delta samples of the FIR design's robust ``|Te1|`` constraint (its default K).
FIR_DESIGN_SAMPLES = 8



def _rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def draw_true_loops(fleet: Fleet, options: CampaignOptions, index: int) -> tuple[dict[str, LoopSystem], int]:
    """Sample ``index``'s true loops, one per vehicle in fleet order, and the redraws of unstable loops
    (and of loops outside ``options.margin``).

    Depends on ``(options.seed, index)``, ``scale``, ``bound`` and ``margin`` only.

    Parameters
    ----------
    fleet : Fleet
        The fleet; each system's identification (or stated or given bound) is sampled.
    options : CampaignOptions
        Its ``seed``, ``scale`` and ``bound`` are used.
    index : int
        The sample, >= 0.

    Returns
    -------
    loops : dict of str to LoopSystem
        The true loop of every system (true plant; controller, Q and M from the model).
    rejected : int
        Draws rejected because their loop was unstable or outside the margin.
    """
    rng = _rng(options.seed, 0, index)
    loops, rejected = {}, 0
    for spec in fleet.systems:
        ds = delta_set(spec, fleet.sample_time, 1, rng, scale=options.scale, bound=options.bound,
                       w=np.array([1.0]), margin=options.margin)
        loops[spec.name], rejected = ds.loops[0], rejected + ds.rejected
    return loops, rejected


def _design_deltas(fleet: Fleet, options: CampaignOptions) -> dict[str, DeltaSet]:
    """The designers' Delta samples: identified uncertainty (scale 1) or the bound, seeded ``(seed, 1)``."""
    k = max(FIR_DESIGN_SAMPLES, options.robust_models, 1)
    rng = _rng(options.seed, 1)
    return {s.name: delta_set(s, fleet.sample_time, k, rng, bound=options.bound, margin=options.margin)
            for s in fleet.systems}


class _WorkerState:
    """Per worker process: the fleet's scenarios and designs of one campaign, built on first use.

    Its threads share it: ``lock`` is held while a scenario or design is built (each is built once)
    and, with the robust method, while a sample is flown (its SOCP designer keeps the state of its
    last solve; local clusters run one thread per worker process, so nobody waits there).
    """

    def __init__(self, fleet: Fleet, options: CampaignOptions):
        self.fleet, self.options = fleet, options
        self.lock = threading.RLock()
        self.pairs: dict[int, PairScenario] = {}
        self.designs: dict[tuple[str, str, str], PairDesign | str] = {}
        self._deltas: dict[str, DeltaSet] | None = None
        self.lawful: dict[tuple[int, str], PairDesign] = {}

    def pair(self, sid: int) -> PairScenario:
        if sid not in self.pairs:
            self.pairs[sid] = pair_scenario(self.fleet, sid, self.options.duration)
        return self.pairs[sid]

    def design(self, source: str, target: str, method: str, n: int) -> PairDesign | str:
        """The design (built once), or the error message of a design that cannot be made."""
        key = (source, target, method)
        if key not in self.designs:
            if self._deltas is None:
                self._deltas = _design_deltas(self.fleet, self.options)
            k = self.options.robust_models if METHODS[method].per_trial else FIR_DESIGN_SAMPLES
            deltas = {name: replace(self._deltas[name], loops=self._deltas[name].loops[:k])
                      for name in (source, target)}
            try:
                # robust-set guarantees over the family the true plants are drawn from (value sets, not samples)
                settings = MethodSettings(n=n, rho=self.options.rho, deltas=deltas,
                                          robust_set=self._robust_set_options())
                self.designs[key] = design_pair(self.fleet, source, target, METHODS[method].configured(settings))
            except IlcdobError as exc:  # e.g. FIR constraint not met: every run of it is recorded as failed
                self.designs[key] = f"design failed: {exc}"
        return self.designs[key]

    def _robust_set_options(self) -> RobustSetOptions:
        """robust-set's options: over the structured family it guarantees over the plants the campaign keeps (its
        margin); the disc and "auto" keep the disc's own margin (``|1 + T0 Delta| >= m``, another quantity)."""
        o = self.options
        rs = RobustSetOptions(rho=o.rho, delta_set=o.delta_set)
        return replace(rs, margin=o.margin) if o.delta_set == "structured" else rs

    def with_law(self, sid: int, method: str, design: PairDesign) -> PairDesign:
        """``design`` learning with the campaign's law on scenario ``sid`` (its reference terms, built once)."""
        if self.options.law == DEFAULT_LAW:
            return design
        if (sid, method) not in self.lawful:
            pair = self.pair(sid)
            self.lawful[(sid, method)] = with_law(design, self.fleet, pair.source, pair.target, self.options.law,
                                                   pair.r, pair.a_ref)
        return self.lawful[(sid, method)]


_STATE: dict[str, _WorkerState] = {}  # settings id -> the state of the campaign this process flies
_STATE_LOCK = threading.Lock()


def _worker_state(fleet: Fleet, options: CampaignOptions, settings_id: str) -> _WorkerState:
    """The process's state of campaign ``settings_id``: one campaign per process (long-lived workers drop the
    previous one's designs when another campaign's samples arrive)."""
    with _STATE_LOCK:
        state = _STATE.get(settings_id)
        if state is None:
            _STATE.clear()
            _STATE[settings_id] = state = _WorkerState(fleet, options)
        return state


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def run_sample(fleet: Fleet, options: CampaignOptions, settings_id: str, index: int) -> dict[str, Any]:
    """Fly sample ``index`` through every scenario with every design (the Dask task).

    Parameters
    ----------
    fleet : Fleet
        The fleet (scattered to the workers).
    options : CampaignOptions
        The campaign's options.
    settings_id : str
        ``id`` of :func:`~ilcdob.validation.campaign.options.campaign_settings`; each worker
        process keeps the designs of one campaign (shared by its threads), rebuilt when the id changes.
    index : int
        The sample, >= 0.

    Returns
    -------
    dict
        The JSON record of the sample: ``{"sample", "settings", "rejected", "plants": {name:
        {"num", "den", "delay"}}, "scenarios": {id: {"source", "target", "rmse_without",
        "ratios": {method: ratio or null}, "errors": {method: message}}}, "time_s", "cpu_s"}``
        (s: wall-clock time, and the CPU time of the thread that flew the sample, :data:`CPU_S`;
        they differ when the cores are shared).
    """
    t0, c0 = time.perf_counter(), time.thread_time()
    state = _worker_state(fleet, options, settings_id)
    # the robust SOCP designer keeps its last solve's state: the process's threads take turns on it
    with state.lock if "robust" in options.methods else nullcontext():
        record = _fly(state, fleet, options, settings_id, index)
    return {**record, "time_s": time.perf_counter() - t0, "cpu_s": time.thread_time() - c0}


def _fly(state: _WorkerState, fleet: Fleet, options: CampaignOptions, settings_id: str,
         index: int) -> dict[str, Any]:
    """:func:`run_sample`'s record without its timings."""
    loops, rejected = draw_true_loops(fleet, options, index)
    scenarios = {}
    for sid in options.scenarios:
        with state.lock:
            pair = state.pair(sid)
        designs, errors = {}, {}
        for method in options.methods:
            with state.lock:  # built once per process
                d = state.design(pair.source, pair.target, method, pair.t.size)
            if isinstance(d, str):
                errors[method] = d
            else:
                with state.lock:
                    designs[method] = state.with_law(sid, method, d)
        case = evaluate_case(pair, loops[pair.source], loops[pair.target], designs)
        errors.update(case.errors)
        scenarios[str(sid)] = {"source": pair.source, "target": pair.target, "rmse_without": case.rmse_without,
                               "ratios": {m: _finite(case.ratios[m]) if m in case.ratios else None
                                          for m in options.methods},
                               "errors": errors}
    plants = {name: {"num": list(lp.spec.plant.num), "den": list(lp.spec.plant.den), "delay": lp.spec.plant.delay}
              for name, lp in loops.items()}
    return {"sample": index, "settings": settings_id, "rejected": rejected, "plants": plants, "scenarios": scenarios}


def _sample_task(fleet: Fleet, options: CampaignOptions, settings_id: str,
                 index: int) -> tuple[dict[str, Any], list[tuple[str, type[Warning], str, int]]]:
    """The Dask task: :func:`run_sample` and the distinct warnings it raised on the worker (text, category,
    file, line), for the client to show through its own warning machinery instead of the worker's stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        record = run_sample(fleet, options, settings_id, index)
    seen = {(str(w.message), w.category): (str(w.message), w.category, w.filename, w.lineno) for w in caught}
    return record, list(seen.values())


def run_campaign(fleet: Fleet, options: CampaignOptions, out: str | Path, scheduler: str | None = None,
                 workers: int | None = None,
                 progress: Callable[[int, int, str], None] | None = None,
                 dashboard: Callable[[str], None] | None = None, *, scheduler_file: str | Path | None = None,
                 tls_ca_file: str | Path | None = None, tls_cert: str | Path | None = None,
                 tls_key: str | Path | None = None) -> CampaignResult:
    """Run (or resume) a campaign whose samples are kept in ``out`` (see :mod:`ilcdob.validation.campaign`).

    The folder holds the campaign's sample store and settings (:mod:`.store`), kept up to date
    sample by sample so that a killed run resumes; the report (:meth:`CampaignResult.files`)
    is not written here.

    Parameters
    ----------
    fleet : Fleet
        Needs at least two systems; identified ones unless ``options.bound`` is given.
    options : CampaignOptions
        The campaign's settings.
    out : str or Path
        The campaign folder (created); holds ``samples.jsonl`` and ``campaign_settings.json``.
    scheduler : str, optional
        ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` of a running Dask scheduler (default: a local cluster).
    workers : int, optional
        Local cluster: worker processes (default: the usable cores).
    progress : callable, optional
        Called as ``progress(done, total, what)``: once before flying (``done``: the samples
        read back from the folder), then after each sample flown; ``total`` is
        ``options.samples``. None: silent.
    dashboard : callable, optional
        Called with one line naming the Dask dashboard link when the cluster is up (a local
        cluster then serves its dashboard on a free port). None: no dashboard.
    scheduler_file : str or Path, optional
        Instead of ``scheduler``: the file ``dask scheduler --scheduler-file`` writes.
    tls_ca_file, tls_cert, tls_key : str or Path, optional
        A ``tls://`` scheduler's TLS files (:class:`~ilcdob.validation.campaign.cluster.Cluster`).

    Returns
    -------
    CampaignResult
        Statistics of samples ``0 .. options.samples - 1``.

    Raises
    ------
    CampaignError
        Bad scheduler address or file, missing TLS files (or TLS without ``tls://``), no connection, a
        worker count beyond :data:`WORKERS_PER_CORE`
        per usable core (or given with a scheduler), ``out`` holding a campaign with other
        settings or in use, a sample failing on a worker (finished samples are kept: run again
        to resume).

    Warns
    -----
    Warning
        What a sample raised on its worker (SciPy, cvxpy, ...), issued again here, once per
        distinct text and category per sample, instead of reaching the worker's stderr.
    """
    t_start = time.perf_counter()
    say = progress if progress is not None else (lambda done, total, what: None)
    cluster = Cluster(scheduler=scheduler, scheduler_file=scheduler_file, tls_ca_file=tls_ca_file,
                      tls_cert=tls_cert, tls_key=tls_key, workers=workers)
    cluster.check()
    if len(fleet.systems) < 2:
        raise CampaignError(f"fleet {fleet.source}: a campaign needs at least two systems, got {fleet.names}")
    if options.bound is None:
        lacking = [s.name for s in fleet.systems if s.identification is None and s.uncertainty is None]
        if lacking:
            raise CampaignError(f"fleet {fleet.source}: systems {lacking} have neither an identification nor an "
                                "`uncertainty = { bound }` to draw true plants from; identify them (ilcdob "
                                "identify-fleet), state a bound in the fleet file, or give one (--bound 0.2)")
    for sid in options.scenarios:  # the scenarios' signals, as every worker cuts them (a bad duration is refused here)
        pair_scenario(fleet, sid, options.duration)
    settings = campaign_settings(fleet, options)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with campaign_lock(out):
        check_settings(out, settings)
        store = SampleStore(out / SAMPLES_FILE, settings["id"])
        records = store.load()
        resumed = sum(1 for i in records if i < options.samples)
        todo = [i for i in range(options.samples) if i not in records]
        n_workers = 0
        total = options.samples
        say(resumed, total, f"campaign: {len(todo)} of {total} samples to fly ({resumed} already in {store.path})")
        if todo:
            with cluster_client(cluster, dashboard is not None) as client:
                if dashboard is not None:
                    dashboard(f"Dask dashboard: {client.dashboard_link}")
                from distributed import as_completed

                n_workers = len(client.scheduler_info()["workers"])
                fleet_f = client.scatter(fleet, broadcast=True)
                futures = [client.submit(_sample_task, fleet_f, options, settings["id"], i, pure=False,
                                         key=f"ilcdob-campaign-{settings['id']}-{i}") for i in todo]
                done = resumed
                for fut in as_completed(futures):
                    try:
                        rec, warned = fut.result()
                    except Exception as exc:  # noqa: BLE001 - any worker failure stops the campaign, resumable
                        for f in futures:
                            f.cancel()
                        kept = (f"the {done} finished samples are kept in {store.path}, run the same command "
                                "again to resume" if done else "no sample had finished, so nothing is kept")
                        raise CampaignError(f"a sample failed on a worker: {type(exc).__name__}: {exc}; "
                                            f"{kept}") from exc
                    for text, category, filename, lineno in warned:  # the client's filters and display decide
                        warnings.warn_explicit(text, category, filename, lineno)
                    store.append(rec)
                    records[rec["sample"]] = rec
                    done += 1
                    say(done, total, f"campaign: sample {rec['sample']} flown ({rec['time_s']:.1f} s on a worker)")
        return campaign_statistics(records, options, settings, resumed, time.perf_counter() - t_start,
                                   n_workers)
