"""Monte Carlo campaigns (`ilcdob campaign`): resumable after a kill, settings guarded, statistics.

Campaigns here are small (few samples, one scenario cut to 10-20 s, two designs, one local
worker) so the file stays well under a minute on 2 cores.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.fleet import load_fleet
from ilcdob.app.html import json_tables
from ilcdob.validation.campaign import (SAMPLES_FILE, SETTINGS_FILE, CampaignError, CampaignOptions,
                                        MethodStatistics, SampleStore, campaign_settings, campaign_statistics,
                                        draw_true_loops, run_campaign, run_sample)

# one scenario of 20 s (1000 samples), closed form + robust SOCP (1 + 1 models): ~0.3 s per sample
KILL_ARGS = ["--samples", "12", "--scenarios", "2", "--methods", "closed-form,robust", "--duration", "20",
             "--robust-models", "1", "--workers", "1", "--seed", "3"]
SMALL = CampaignOptions(samples=2, scenarios=(1,), methods=("closed-form",), duration=4.0)
# the same campaign through the library: run_campaign in a child process, killed mid-run
LIBRARY_KILL = dict(samples=10, scenarios=(2,), methods=("closed-form", "robust"), duration=20.0, robust_models=1,
                    seed=3)
_LIBRARY_CHILD = """
import sys
from ilcdob.fleet import default_fleet
from ilcdob.validation.campaign import CampaignOptions, run_campaign
run_campaign(default_fleet(), CampaignOptions(**{opts!r}), sys.argv[1], workers=1)
"""


def _campaign(out: Path, *, wait: bool = True) -> subprocess.Popen:
    """``python -P -m ilcdob campaign`` in its own process group (client and its worker processes)."""
    proc = subprocess.Popen([sys.executable, "-P", "-m", "ilcdob", "campaign", *KILL_ARGS, "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    if wait:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
    return proc


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines() if path.exists() else []


def _results(rec: dict) -> dict:
    """A record without its timings (which differ run to run)."""
    return {k: v for k, v in rec.items() if k not in ("time_s", "cpu_s")}


@pytest.mark.slow  # 20 s (-m slow); by default test_examples resumes a finished campaign from its store
def test_killed_campaign_resumes_to_the_statistics_of_an_uninterrupted_run(tmp_path):
    killed, clean = tmp_path / "killed", tmp_path / "clean"
    proc = _campaign(killed, wait=False)
    samples = killed / SAMPLES_FILE
    deadline = time.monotonic() + 240
    while len(_lines(samples)) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the client and its Dask workers, mid-run
    proc.communicate()
    written = len(_lines(samples))
    assert 3 <= written < 12, f"the kill came at {written} of 12 samples; expected mid-run"
    assert not (killed / "campaign.json").exists()
    with open(samples, "a") as f:  # a line torn by a kill during the write
        f.write('{"sample": 11, "settings": "')

    _campaign(killed)  # resumes: flies only the missing samples
    _campaign(clean)   # the same campaign, uninterrupted

    recs = [json.loads(line) for line in _lines(samples)]
    assert sorted(r["sample"] for r in recs) == list(range(12))  # none lost, none duplicated
    ref = {r["sample"]: r for r in map(json.loads, _lines(clean / SAMPLES_FILE))}
    assert all(_results(r) == _results(ref[r["sample"]]) for r in recs)
    a, b = (json.loads((d / "campaign.json").read_text()) for d in (killed, clean))
    assert a["methods"] == b["methods"] and a["scenarios"] == b["scenarios"]
    assert a["resumed_samples"] == written and b["resumed_samples"] == 0
    assert a["methods"]["robust"]["runs"] == 12 and a["methods"]["robust"]["share_improved"] == 1.0
    assert (killed / "campaign_ratios.png").stat().st_size > 1000
    # the HTML report's generic renderer finds the per-method and per-scenario tables
    paths = [t.path for t in json_tables(a)]
    assert "methods" in paths and any(p.startswith("scenarios.") for p in paths)


@pytest.mark.slow  # 15 s (-m slow); the command-line kill-and-resume test above covers the same store
def test_killed_library_campaign_resumes_to_an_uninterrupted_run(fleet, tmp_path):
    """``run_campaign`` keeps the sample store up to date: killed mid-run (client and workers), it resumes
    with only the missing samples and gives the statistics and report of an uninterrupted run."""
    killed, clean = tmp_path / "killed", tmp_path / "clean"
    proc = subprocess.Popen([sys.executable, "-P", "-c", _LIBRARY_CHILD.format(opts=LIBRARY_KILL), str(killed)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    samples = killed / SAMPLES_FILE
    deadline = time.monotonic() + 240
    while len(_lines(samples)) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate()
    written = len(_lines(samples))
    assert 3 <= written < 10, f"the kill came at {written} of 10 samples; expected mid-run"
    with open(samples, "a") as f:  # a line torn by a kill during the write
        f.write('{"sample": 9, "settings": "')

    opts = CampaignOptions(**LIBRARY_KILL)
    calls = []
    resumed = run_campaign(fleet, opts, killed, workers=1, progress=lambda *call: calls.append(call))
    assert calls[0][:2] == (written, 10) and [c[0] for c in calls[1:]] == list(range(written + 1, 11))
    uninterrupted = run_campaign(fleet, opts, clean, workers=1)

    recs = [json.loads(line) for line in _lines(samples)]
    assert sorted(r["sample"] for r in recs) == list(range(10))  # none lost, none duplicated
    ref = {r["sample"]: r for r in map(json.loads, _lines(clean / SAMPLES_FILE))}
    assert all(_results(r) == _results(ref[r["sample"]]) for r in recs)
    assert resumed.resumed == written and uninterrupted.resumed == 0
    assert resumed.methods == uninterrupted.methods and resumed.scenarios == uninterrupted.scenarios
    a, b = resumed.files(), uninterrupted.files()
    assert a["campaign.txt"] == b["campaign.txt"]
    assert a["campaign.json"]["methods"] == b["campaign.json"]["methods"]
    assert a["campaign.json"]["methods"]["robust"]["runs"] == 10
    assert not (killed / "campaign.json").exists()  # the report is the caller's to write


def test_files_are_the_report_content(fleet):
    """``CampaignResult.files(figures)``: campaign.json (standard JSON), campaign.txt and the figures the
    application composes (campaign_ratios.png)."""
    from matplotlib.figure import Figure

    from ilcdob.validation.figures import campaign_figure

    settings = campaign_settings(fleet, SMALL)
    rec = {"sample": 0, "settings": settings["id"], "rejected": 0, "time_s": 1.0, "cpu_s": 1.0,
           "scenarios": {"1": {"source": "UAV1", "target": "UAV2", "rmse_without": 0.1,
                               "ratios": {"closed-form": 0.02}, "errors": {}}}}
    records = {0: rec, 1: {**rec, "sample": 1}}
    result = campaign_statistics(records, SMALL, settings)  # wall time unknown: NaN
    assert list(result.files()) == ["campaign.json", "campaign.txt"]
    files = result.files({"campaign_ratios.png": campaign_figure(result)})
    assert list(files) == ["campaign.json", "campaign.txt", "campaign_ratios.png"]
    data = files["campaign.json"]
    assert data["wall_time_s"] is None and data["methods"]["closed-form"]["median"] == pytest.approx(0.02)
    json.dumps(data, allow_nan=False)
    assert files["campaign.txt"] == result.table()
    assert isinstance(files["campaign_ratios.png"], Figure)


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
def test_settings_guard_and_extension(fleet, tmp_path):
    out = tmp_path / "c"
    first = run_campaign(fleet, SMALL, out, workers=1)
    assert first.methods["closed-form"].runs == 2 and first.resumed == 0
    with pytest.raises(CampaignError, match=r"different settings \(seed: 0 there, 1 now\).*another --out"):
        run_campaign(fleet, replace(SMALL, seed=1), out, workers=1)
    more = run_campaign(fleet, replace(SMALL, samples=3), out, workers=1)  # a larger N extends the campaign
    assert more.resumed == 2 and more.methods["closed-form"].runs == 3
    assert len(_lines(out / SAMPLES_FILE)) == 3
    # a resumed run with nothing left to fly starts no cluster and reproduces the statistics
    again = run_campaign(fleet, SMALL, out)
    assert again.workers == 0 and again.methods == first.methods
    (out / SETTINGS_FILE).unlink()
    with pytest.raises(CampaignError, match="settings are unknown"):
        run_campaign(fleet, SMALL, out, workers=1)


def test_margin_enters_the_settings_only_when_it_changes_the_draws(fleet):
    """``margin = 0`` (every stable plant) is how campaigns sampled before the option: their ids stay."""
    ids = {m: campaign_settings(fleet, replace(SMALL, margin=m))["id"] for m in (0.0, 0.5, 0.3)}
    assert len(set(ids.values())) == 3
    before = campaign_settings(fleet, replace(SMALL, margin=0.0))
    assert "margin" not in before and campaign_settings(fleet, SMALL)["margin"] == 0.5


def test_sample_store_drops_a_torn_line_and_refuses_foreign_records(tmp_path):
    store = SampleStore(tmp_path / SAMPLES_FILE, "abc")
    store.append({"sample": 0, "settings": "abc", "x": 1})
    store.append({"sample": 1, "settings": "abc", "x": 2})
    with open(store.path, "a") as f:
        f.write('{"sample": 2, "sett')
    assert sorted(store.load()) == [0, 1]
    assert store.path.read_text().endswith("}\n")  # cut back to the last complete line
    store.append({"sample": 1, "settings": "abc", "x": 2})  # an identical duplicate is harmless
    assert sorted(store.load()) == [0, 1]
    store.append({"sample": 1, "settings": "abc", "x": 3})
    with pytest.raises(CampaignError, match="second, different record of sample 1"):
        store.load()
    with pytest.raises(CampaignError, match="line 1: not a sample record of campaign xyz"):
        SampleStore(store.path, "xyz").load()


def test_samples_depend_on_seed_and_index_only(fleet):
    opts = CampaignOptions(samples=5, seed=7)
    a, _ = draw_true_loops(fleet, opts, 3)
    b, _ = draw_true_loops(fleet, CampaignOptions(samples=50, seed=7, methods=("fir",)), 3)
    c, _ = draw_true_loops(fleet, opts, 4)
    assert all(a[n].spec.plant == b[n].spec.plant for n in fleet.names)
    assert a["UAV1"].spec.plant != c["UAV1"].spec.plant
    wide, _ = draw_true_loops(fleet, CampaignOptions(seed=7, scale=3.0), 3)  # same draw, 3x the deviation
    nominal = fleet.systems[0].plant.num[0]
    assert abs(wide["UAV1"].spec.plant.num[0] - nominal) == pytest.approx(3 * abs(a["UAV1"].spec.plant.num[0]
                                                                                   - nominal), rel=1e-6)


def test_statistics_count_failed_runs_as_not_improved():
    s = MethodStatistics.of([0.5, 2.0, None, 0.1])
    assert (s.runs, s.failed, s.worst, s.share_improved) == (4, 1, 2.0, 0.5)
    assert s.median == pytest.approx(0.5) and s.p95 == pytest.approx(np.percentile([0.5, 2.0, 0.1], 95))
    assert MethodStatistics.of([None]).to_dict()["median"] is None


def test_bad_inputs(fleet, fleet_file, tmp_path, capsys):
    for kwargs, name in [({"samples": 0}, "samples"), ({"methods": ("closed-form", "magic")}, "magic"),
                         ({"scenarios": (7,)}, "scenarios"), ({"robust_models": -1}, "robust_models"),
                         ({"scale": 0.0}, "scale"), ({"duration": -1.0}, "duration"), ({"margin": 1.0}, "margin")]:
        with pytest.raises(CampaignError, match=name):
            CampaignOptions(**kwargs)
    with pytest.raises(CampaignError, match=r"`scheduler`: got 'localhost:8786'.*tcp://HOST:PORT"):
        run_campaign(fleet, SMALL, tmp_path / "s", scheduler="localhost:8786")
    assert not (tmp_path / "s").exists()
    unidentified = load_fleet(fleet_file())  # two systems, no identification, no stated bound
    with pytest.raises(CampaignError, match=r"\['A', 'B'\] have neither an identification.*--bound"):
        run_campaign(unidentified, SMALL, tmp_path / "u")
    assert main(["campaign", "--samples", "2", "--methods", "fir,bogus", "--out", str(tmp_path / "m")]) == 2
    assert "bogus" in capsys.readouterr().err
    assert main(["campaign", "--samples", "0", "--out", str(tmp_path / "z")]) == 2  # a usage error
    assert "--samples: got '0', expected an integer >= 1" in capsys.readouterr().err


@pytest.mark.slow  # 7 s (-m slow); the campaign's cluster path, the rest of the campaign runs by default
def test_runs_on_an_existing_cluster(fleet, tmp_path):
    """``--scheduler tcp://HOST:PORT``: the samples go to that cluster's workers, and give the same records."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp",
                      host="127.0.0.1", dashboard_address=None) as cluster:
        res = run_campaign(fleet, SMALL, tmp_path / "ext", scheduler=cluster.scheduler_address)
    assert res.workers == 1 and res.methods["closed-form"].runs == 2
    local = run_campaign(fleet, SMALL, tmp_path / "loc", workers=1)
    assert local.methods == res.methods


def test_runs_through_a_scheduler_file_with_the_workers_threads_limited(fleet, tmp_path):
    """``scheduler_file``: the file ``dask scheduler --scheduler-file`` writes names the cluster; its workers get
    BLAS and Clarabel limited to one thread (a worker plugin, undone when the in-process worker closes)."""
    from distributed import LocalCluster
    from threadpoolctl import threadpool_info

    from ilcdob.design.methods import robust, robust_set

    path = tmp_path / "scheduler.json"
    blas_before = [i["num_threads"] for i in threadpool_info()]
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address=None, scheduler_kwargs={"scheduler_file": str(path)}):
        assert json.loads(path.read_text())["address"].startswith("tcp://")
        res = run_campaign(fleet, SMALL, tmp_path / "f", scheduler_file=path)
        assert robust.CLARABEL_THREADS == robust_set.CLARABEL_THREADS == 1  # the worker is this process
        assert all(i["num_threads"] == 1 for i in threadpool_info())
    assert res.workers == 1 and res.methods["closed-form"].runs == 2
    assert robust.CLARABEL_THREADS == robust_set.CLARABEL_THREADS == 0
    assert [i["num_threads"] for i in threadpool_info()] == blas_before
    report = res.to_dict()
    assert report["library_threads"]["blas"] == report["library_threads"]["clarabel"] == 1
    assert "thread_time" in report["cpu_s"]


def test_cluster_options_are_checked_before_connecting(fleet, tmp_path, capsys):
    """A missing or address-less scheduler file, both a scheduler and a file, TLS files without a tls://
    scheduler (or missing), a tls:// scheduler without them: refused by name, nothing written."""
    pem = tmp_path / "ca.pem"
    pem.write_text("not checked before connecting")
    missing = tmp_path / "nowhere.json"
    cases = [({"scheduler_file": missing}, "nowhere.json"),
             ({"scheduler": "tcp://127.0.0.1:8786", "scheduler_file": missing}, "give one of them"),
             ({"tls_ca_file": pem, "tls_cert": pem}, r"TLS files go with a tls:// scheduler, got a local cluster"),
             ({"scheduler": "tcp://127.0.0.1:8786", "tls_ca_file": pem, "tls_cert": pem},
              r"`tls_ca_file`, `tls_cert`: TLS files go with a tls:// scheduler, got 'tcp://127.0.0.1:8786'"),
             ({"scheduler": "tls://127.0.0.1:8786"}, "needs tls_ca_file and tls_cert"),
             ({"scheduler": "tls://127.0.0.1:8786", "tls_ca_file": pem, "tls_cert": tmp_path / "no.pem"},
              r"`tls_cert`: got '.*no\.pem' \(no such file\)")]
    for kwargs, message in cases:
        with pytest.raises(CampaignError, match=message):
            run_campaign(fleet, SMALL, tmp_path / "out", **kwargs)
    (tmp_path / "bare.json").write_text('{"type": "Scheduler"}')
    with pytest.raises(CampaignError, match=r"bare\.json: no \"address\""):
        run_campaign(fleet, SMALL, tmp_path / "out", scheduler_file=tmp_path / "bare.json")
    assert not (tmp_path / "out").exists()
    assert main(["campaign", "--samples", "2", "--scheduler-file", str(missing), "--out", str(tmp_path / "c")]) == 2
    assert "nowhere.json" in capsys.readouterr().err
    assert main(["campaign", "--samples", "2", "--scheduler", "tcp://127.0.0.1:8786", "--scheduler-file",
                 str(missing), "--out", str(tmp_path / "c")]) == 2
    assert "--scheduler-file: not allowed with argument --scheduler" in capsys.readouterr().err


def test_cpu_s_is_the_samples_thread_time(fleet, monkeypatch):
    """``cpu_s`` counts the thread that flew the sample, not the whole worker process (its other threads)."""
    import time as time_module

    thread, process = iter([10.0, 12.5]), iter([0.0, 100.0])
    monkeypatch.setattr(time_module, "thread_time", lambda: next(thread))
    monkeypatch.setattr(time_module, "process_time", lambda: next(process))
    rec = run_sample(fleet, SMALL, campaign_settings(fleet, SMALL)["id"], 0)
    assert rec["cpu_s"] == 2.5


def test_designs_are_shared_by_the_threads_of_a_worker_process(fleet):
    """One state (scenarios, designs) per process and campaign: a second thread reuses the first one's."""
    import threading

    from ilcdob.validation.campaign import run as campaign_run

    states = []
    threads = [threading.Thread(target=lambda: states.append(campaign_run._worker_state(fleet, SMALL, "one")))
               for _ in range(2)]
    for t in threads:
        t.start()
        t.join()
    assert states[0] is states[1]
    assert campaign_run._worker_state(fleet, SMALL, "two") is not states[0]  # another campaign: rebuilt


def _self_signed(folder: Path) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 that is its own CA, and its key (PEM files)."""
    import datetime
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "ilcdob-test")])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(days=1))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .add_extension(x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
                                                        x509.DNSName("localhost")]), critical=False)
            .sign(key, hashes.SHA256()))
    cert_file, key_file = folder / "cert.pem", folder / "key.pem"
    cert_file.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_file.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    return cert_file, key_file


def test_runs_on_a_tls_cluster(fleet, tmp_path):
    """``tls://`` scheduler with ``tls_ca_file``, ``tls_cert``, ``tls_key``: the client connects with
    them (a self-signed certificate, its own CA, for scheduler, worker and client)."""
    pytest.importorskip("cryptography", reason="generates the test's self-signed certificate")
    from distributed import LocalCluster
    from distributed.security import Security

    cert, key = _self_signed(tmp_path)
    security = Security(tls_ca_file=str(cert), tls_scheduler_cert=str(cert), tls_scheduler_key=str(key),
                        tls_worker_cert=str(cert), tls_worker_key=str(key), tls_client_cert=str(cert),
                        tls_client_key=str(key), require_encryption=True)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tls", host="127.0.0.1",
                      dashboard_address=None, security=security) as cluster:
        assert cluster.scheduler_address.startswith("tls://")
        res = run_campaign(fleet, SMALL, tmp_path / "tls", scheduler=cluster.scheduler_address, tls_ca_file=cert,
                           tls_cert=cert, tls_key=key)
    assert res.workers == 1 and res.methods["closed-form"].runs == 2
