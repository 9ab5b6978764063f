"""Monte Carlo campaigns: every design, every scenario, many sampled true plants, on Dask.

A campaign of ``N`` samples answers "how often, and by how much, does each learning design
help when the vehicles are not what their models say?". Sample ``i`` draws one true plant per
vehicle of the fleet from its identified uncertainty (:func:`ilcdob.design.delta_set`:
parameters from the fit's Gaussian ``N(theta, scale^2 Cov)``; ``scale`` > 1 goes beyond the
identified uncertainty; or a multiplicative ``bound`` for fleets without identification),
from a generator seeded by ``(seed, i)`` only, so a sample is the same whichever worker flies
it and whenever. For every scenario the first pair of its learning order (j-1 -> j) is
flown as in :func:`ilcdob.validation.compare.evaluate_case`: system j-1 flies its DOB-only
trial under its true plant, every design turns the trial into system j's learning signal,
and system j flies with and without it under its true plant. The figure of merit is the
paper's improvement ratio ``||e_j|| / ||e'_j||`` over whole trials (Theorem: < 1 means learning
helped).

The designs only know the models: closed-form and norm-optimal are built from the nominal
models, FIR from the nominal models and 8 samples of the identified uncertainty (its robust
``|Te1|`` constraint), robust from the nominal pair plus ``robust_models`` paired samples
(its SOCP is solved per trial), robust-set from the nominal models and the Delta set's bound
(:mod:`ilcdob.design.methods.robust_set`; its rho is ``rho``, which must then lie in (0, 1]). These design samples are
drawn once from ``(seed, design)`` at scale 1 (the identified uncertainty, which is what a
designer knows) and are never the true plants of a sample. Every design is built once per
worker and pair and reused for all its samples and scenarios; only the robust SOCP is
re-solved per trial.

The campaign keeps its samples in its folder ``DIR`` while it runs (:mod:`.store`): one
JSON line per finished sample, appended, flushed and fsynced to ``DIR/samples.jsonl`` by the
one client process (a lock on that file keeps a second campaign out of ``DIR``). A campaign
killed at any point is resumed by running it again: finished samples are read back (a line
torn by the kill is dropped), only the missing ones are flown, and since each sample depends
on ``(seed, i)`` alone the statistics are those of an uninterrupted run.
``DIR/campaign_settings.json`` records the settings; a run with different settings (other
than a larger ``samples``, which extends the campaign) is refused. The settings do not cover
the code: resume with the ilcdob that started the campaign (a changed design gives other
ratios for the samples still to fly).

:func:`run_campaign` returns the statistics (:class:`CampaignResult`: median, 95th
percentile, worst ratio and share of runs that improved, per method and per scenario x
method); its report, :meth:`CampaignResult.files` (``campaign.json``, ``campaign.txt``,
``campaign_ratios.png``), is content for the caller to write.

Dask: a local cluster (``distributed.LocalCluster``, one single-threaded worker process per
core) unless a running cluster is named by its scheduler's address (``tcp://`` or ``tls://``
with its TLS files) or scheduler file (:mod:`.cluster`); its workers need ilcdob installed.
Each worker process builds the designs once and shares them among its threads, with BLAS and
Clarabel limited to one thread (a worker plugin); a record's ``cpu_s`` is the CPU time of the
thread that flew it.

Modules: :mod:`.options` (settings and their identity), :mod:`.cluster` (the Dask connection
and the workers' thread limits), :mod:`.run` (sampling, the workers' state,
:func:`run_campaign`), :mod:`.store` (the sample store, the settings
file, the folder lock), :mod:`.statistics` (the statistics and the report).
"""

from .cluster import Cluster
from .options import FORMAT_VERSION, CampaignError, CampaignOptions, campaign_settings
from .run import FIR_DESIGN_SAMPLES, draw_true_loops, run_campaign, run_sample
from .statistics import CampaignResult, MethodStatistics, campaign_statistics
from .store import SAMPLES_FILE, SETTINGS_FILE, STORE_FILES, SampleStore

__all__ = ["Cluster", "CampaignError", "CampaignOptions", "CampaignResult", "MethodStatistics", "SampleStore",
           "campaign_settings", "draw_true_loops", "run_sample", "campaign_statistics", "run_campaign",
           "SAMPLES_FILE", "SETTINGS_FILE", "STORE_FILES", "FORMAT_VERSION", "FIR_DESIGN_SAMPLES"]
