"""Where a campaign's samples fly: the Dask connection (scheduler address or file, TLS) and its workers' thread limits.

A campaign runs on a new local cluster (one single-threaded worker process per core), or on a
running cluster named by its scheduler's address ``tcp://HOST:PORT`` / ``tls://HOST:PORT`` or
by the scheduler file ``dask scheduler --scheduler-file PATH`` writes. A ``tls://`` scheduler
takes the TLS files Dask documents (:class:`distributed.security.Security`): the CA
certificate, this client's certificate and, unless that file holds it too, its private key,
all checked before connecting.

On every worker a plugin (``ThreadLimits``, a ``distributed.WorkerPlugin``) limits BLAS and Clarabel's KKT solver to
:data:`LIBRARY_THREADS` thread in the worker's process: the samples are the parallelism.
"""

from __future__ import annotations

import logging
import os
import re
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from ilcdob.extras import require
from ilcdob.inputs import read_json

from .options import CampaignError

__all__ = ["LIBRARY_THREADS", "WORKERS_PER_CORE", "Cluster", "limit_library_threads", "cluster_client"]

#: Most local worker processes per usable core (more only share the cores, each with its own libraries).
WORKERS_PER_CORE = 2
#: Threads of BLAS (threadpoolctl) and of Clarabel's KKT solver in each worker process: the samples are the
#: parallelism, one per worker thread, so libraries that spread over every core would only oversubscribe them.
LIBRARY_THREADS = 1
_SCHEDULER_RE = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")
_THREADPOOL_LIMITS: list[Any] = []  # the process's threadpoolctl limits, kept referenced for its life


def limit_library_threads(threads: int = LIBRARY_THREADS) -> dict[str, int]:
    """Limit BLAS/OpenMP (:func:`threadpoolctl.threadpool_limits`) and Clarabel's KKT solver
    (:data:`ilcdob.design.methods.robust.CLARABEL_THREADS`,
    :data:`ilcdob.design.methods.robust_set.CLARABEL_THREADS`) to
    ``threads`` threads in this process, for its life.

    Parameters
    ----------
    threads : int
        Threads per library, >= 1.

    Returns
    -------
    dict of str to int
        The limits now in force: ``{"blas": threads, "clarabel": threads}``.
    """
    from threadpoolctl import threadpool_limits

    from ilcdob.design.methods import robust, robust_set

    _THREADPOOL_LIMITS[:] = [threadpool_limits(limits=threads)]
    robust.CLARABEL_THREADS = robust_set.CLARABEL_THREADS = threads
    return {"blas": threads, "clarabel": threads}


def _library_threads() -> tuple[list[Any], int, int]:
    """The process's thread limits now: threadpoolctl's, Clarabel's in robust and robust_set."""
    from ilcdob.design.methods import robust, robust_set

    return list(_THREADPOOL_LIMITS), robust.CLARABEL_THREADS, robust_set.CLARABEL_THREADS


def _restore_library_threads(before: tuple[list[Any], int, int]) -> None:
    """Put back the limits :func:`_library_threads` returned."""
    from ilcdob.design.methods import robust, robust_set

    for limits in _THREADPOOL_LIMITS:
        limits.restore_original_limits()
    _THREADPOOL_LIMITS[:] = before[0]
    robust.CLARABEL_THREADS, robust_set.CLARABEL_THREADS = before[1], before[2]


def _thread_limits_class() -> type:
    """:class:`ThreadLimits`, made on first use: it subclasses ``distributed``'s ``WorkerPlugin`` (Dask refuses
    duck-typed plugins), and ``distributed`` is imported only when a campaign runs."""
    global _THREAD_LIMITS
    if _THREAD_LIMITS is None:
        from distributed.diagnostics.plugin import WorkerPlugin

        class ThreadLimits(WorkerPlugin):
            """Dask worker plugin: :func:`limit_library_threads` in the worker's process when the worker starts
            (or joins later).

            Parameters
            ----------
            threads : int
                Threads per library (default :data:`LIBRARY_THREADS`).
            """

            name = "ilcdob-campaign-thread-limits"
            idempotent = True

            def __init__(self, threads: int = LIBRARY_THREADS) -> None:
                self.threads = threads

            def setup(self, worker: Any = None) -> None:
                """Limit the libraries' threads of this worker's process.

                Parameters
                ----------
                worker : distributed.Worker, optional
                    The worker (unused: the limits are the process's).
                """
                self._before = _library_threads()
                limit_library_threads(self.threads)

            def teardown(self, worker: Any = None) -> None:
                """Undo the limits (matters for a worker in the client's own process).

                Parameters
                ----------
                worker : distributed.Worker, optional
                    The worker (unused).
                """
                before = getattr(self, "_before", None)
                if before is not None:
                    _restore_library_threads(before)

        # pickled by reference: the worker finds the class through the module's __getattr__
        ThreadLimits.__module__, ThreadLimits.__qualname__ = __name__, "ThreadLimits"
        _THREAD_LIMITS = ThreadLimits
    return _THREAD_LIMITS


_THREAD_LIMITS: type | None = None


def __getattr__(name: str) -> Any:
    """``ThreadLimits``: the worker plugin class (:func:`_thread_limits_class`)."""
    if name == "ThreadLimits":
        return _thread_limits_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class Cluster:
    """Where a campaign flies: a local cluster, or a running one named by its scheduler.

    Attributes
    ----------
    scheduler : str, optional
        Scheduler address ``tcp://HOST:PORT`` or ``tls://HOST:PORT``.
    scheduler_file : str or Path, optional
        The JSON file ``dask scheduler --scheduler-file`` writes (its ``address``); not with ``scheduler``.
    tls_ca_file, tls_cert, tls_key : str or Path, optional
        TLS files (PEM) for a ``tls://`` scheduler: the CA certificate, the client's certificate and its
        private key (omitted when the certificate file holds it too).
    workers : int, optional
        Local cluster only: worker processes, 1 to :data:`WORKERS_PER_CORE` per usable core (default: the
        usable cores).
    """

    scheduler: str | None = None
    scheduler_file: str | Path | None = None
    tls_ca_file: str | Path | None = None
    tls_cert: str | Path | None = None
    tls_key: str | Path | None = None
    workers: int | None = None

    @property
    def local(self) -> bool:
        """True for a new local cluster (no scheduler given)."""
        return self.scheduler is None and self.scheduler_file is None

    @property
    def tls(self) -> bool:
        """True when TLS files are given."""
        return any(f is not None for f in (self.tls_ca_file, self.tls_cert, self.tls_key))

    def address(self) -> str | None:
        """The scheduler's address, checked (read from the scheduler file if given); None for a local cluster.

        Returns
        -------
        str or None

        Raises
        ------
        CampaignError
            Both a scheduler and a scheduler file, a missing or unreadable scheduler file or one without an
            address, a malformed address.
        """
        if self.scheduler is not None and self.scheduler_file is not None:
            raise CampaignError(f"`scheduler` {self.scheduler!r} and `scheduler_file` {str(self.scheduler_file)!r}: "
                                "give one of them (--scheduler ADDRESS or --scheduler-file PATH)")
        if self.scheduler_file is not None:
            hint = "expected the JSON file `dask scheduler --scheduler-file PATH` writes, with its \"address\""
            doc = read_json(self.scheduler_file, "Dask scheduler file", error=CampaignError, hint=hint)
            address = doc.get("address") if isinstance(doc, dict) else None
            if not isinstance(address, str):
                raise CampaignError(f"scheduler file {self.scheduler_file}: no \"address\" string in it; {hint}")
            _check_scheduler(address, f"`address` in scheduler file {self.scheduler_file}")
            return address
        if self.scheduler is not None:
            _check_scheduler(self.scheduler, "`scheduler`")
        return self.scheduler

    def check(self) -> str | None:
        """Check everything that can be checked before connecting: the address, the worker count, the TLS files.

        Returns
        -------
        str or None
            The scheduler's address (None: a local cluster).

        Raises
        ------
        CampaignError
            What :meth:`address` refuses; a worker count that is not an integer from 1 to
            :data:`WORKERS_PER_CORE` times the usable cores, or one given with a scheduler; TLS files without a
            ``tls://`` scheduler, a ``tls://`` scheduler without them, a missing or unreadable TLS file.
        """
        address = self.address()
        _check_workers(self.workers, address)
        given = {"tls_ca_file": self.tls_ca_file, "tls_cert": self.tls_cert, "tls_key": self.tls_key}
        if self.tls and (address is None or not address.startswith("tls://")):
            named = ", ".join(f"`{k}`" for k, v in given.items() if v is not None)
            raise CampaignError(f"{named}: TLS files go with a tls:// scheduler, got "
                                f"{'a local cluster' if address is None else repr(address)}; give the scheduler's "
                                "tls://HOST:PORT (--scheduler or --scheduler-file), or drop the TLS options")
        if address is not None and address.startswith("tls://"):
            lacking = [k for k in ("tls_ca_file", "tls_cert") if given[k] is None]
            if lacking:
                raise CampaignError(f"`scheduler` {address}: a tls:// scheduler needs {' and '.join(lacking)} "
                                    "(--tls-ca-file CA.pem --tls-cert CLIENT.pem [--tls-key KEY.pem]: the CA that "
                                    "signed the cluster's certificates, this client's certificate and key)")
        for name, path in given.items():
            if path is not None and not (os.path.isfile(path) and os.access(path, os.R_OK)):
                why = "no such file" if not os.path.exists(path) else "not a readable file"
                raise CampaignError(f"`{name}`: got {str(path)!r} ({why}); expected a PEM file")
        return address

    def security(self) -> Any:
        """The :class:`distributed.security.Security` of the TLS files (encryption required), or None.

        Returns
        -------
        distributed.security.Security or None
        """
        if not self.tls:
            return None
        from distributed.security import Security

        return Security(tls_ca_file=str(self.tls_ca_file), tls_client_cert=str(self.tls_cert),
                        tls_client_key=None if self.tls_key is None else str(self.tls_key), require_encryption=True)


def _check_scheduler(address: str, what: str) -> None:
    m = _SCHEDULER_RE.match(address)
    if not m or not 0 < int(m.group(3)) < 65536:
        raise CampaignError(f"{what}: got {address!r}, expected a Dask scheduler address tcp://HOST:PORT or "
                            "tls://HOST:PORT (e.g. tcp://10.0.0.5:8786, printed by `dask scheduler`), or none for a "
                            "local cluster")


def _check_workers(workers: int | None, address: str | None) -> None:
    """Refuse a worker count that is not an integer from 1 to :data:`WORKERS_PER_CORE` times the usable cores,
    or one given with a scheduler (whose cluster has its own workers)."""
    if workers is None:
        return
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise CampaignError(f"`workers`: got {workers!r}, expected an integer >= 1")
    if address is not None:
        raise CampaignError(f"`workers`: got {workers} with `scheduler` {address}: the cluster there has its own "
                            "workers; omit --workers (it sizes a local cluster only)")
    cores = len(os.sched_getaffinity(0))
    if workers > WORKERS_PER_CORE * cores:
        raise CampaignError(f"`workers`: got {workers}, expected 1 to {WORKERS_PER_CORE * cores} local worker "
                            f"processes ({WORKERS_PER_CORE} per usable core, {cores} here): each is a Python process "
                            "with its own copy of the libraries, and more than the cores only share them; for more, "
                            "run a Dask cluster and give its --scheduler")


@contextmanager
def cluster_client(cluster: Cluster, dashboard: bool = False) -> Iterator[Any]:
    """A Dask client on a new local cluster (its dashboard on a free port if asked) or connected to the
    cluster's scheduler, with the ``ThreadLimits`` plugin registered on its workers.

    Parameters
    ----------
    cluster : Cluster
        Where to fly.
    dashboard : bool
        Serve a local cluster's dashboard.

    Yields
    ------
    distributed.Client

    Raises
    ------
    CampaignError
        As :meth:`Cluster.check`; no connection to the scheduler.
    """
    distributed = require("distributed", "campaign", "a campaign (it runs on a Dask cluster)")
    address = cluster.check()
    if address is not None:
        where = f"scheduler file {cluster.scheduler_file}" if cluster.scheduler_file is not None else "--scheduler"
        try:
            client = distributed.Client(address, timeout="10s", security=cluster.security())
        except (OSError, TimeoutError) as exc:
            raise CampaignError(f"`scheduler`: cannot connect to {address} (from {where}; {exc}); is `dask "
                                "scheduler` running there and reachable (and its TLS files the cluster's)? Omit it "
                                "for a local cluster") from None
        try:
            client.register_plugin(_thread_limits_class()())
            yield client
        finally:
            client.close()
        return
    n = cluster.workers if cluster.workers is not None else len(os.sched_getaffinity(0))
    # the workers log nothing (a failed sample's traceback too): the failure reaches the client as its exception
    with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                  dashboard_address=":0" if dashboard else None,
                                  silence_logs=logging.CRITICAL) as local, distributed.Client(local) as client:
        client.register_plugin(_thread_limits_class()())
        yield client
