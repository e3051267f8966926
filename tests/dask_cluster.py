"""A two-worker Dask cluster in this process, for the tests of the Dask paths (skipped without `distributed`).

Threads, not processes: the cluster starts in well under a second; the scheduler and the client still talk over
loopback TCP, so the address path is the one a real cluster uses. The workers' sampling profiler is off: it calls
`sys._current_frames()` every 10 ms, which on CPython 3.11 can deadlock against the garbage collector when workers
share the process (a suite run hung on it, every thread waiting)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import pytest


@contextlib.contextmanager
def in_process_cluster() -> Iterator[object]:
    """Yields a `distributed.Client` connected to the cluster; closes both."""
    distributed = pytest.importorskip("distributed")
    import dask

    with dask.config.set({"distributed.worker.profile.enabled": False}):
        cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                           host="127.0.0.1", dashboard_address=None, silence_logs=40)
        try:
            with distributed.Client(cluster) as client:
                yield client
        finally:
            cluster.close()
