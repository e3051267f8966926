"""analysis.parallel: results in item order on the local pool, in-process, and on a local Dask cluster (skipped when
Dask, the optional extra, is not installed); errors propagate; bad arguments are one-line ConfigErrors."""

from __future__ import annotations

import os

import pytest

from analysis.parallel import default_jobs, parallel_map
from hamr_bench.errors import ConfigError
from tests.dask_cluster import in_process_cluster


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def _square_on_worker(x: int) -> tuple[int, str]:
    from distributed import get_worker

    return x * x, get_worker().address


def _fails_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("item 3 is bad")
    return x


def test_in_process_keeps_order_and_reports_progress():
    seen = []
    out = parallel_map(_square_and_pid, range(5), jobs=1, progress=lambda d, n: seen.append((d, n)))
    assert [v for v, _ in out] == [0, 1, 4, 9, 16]
    assert {pid for _, pid in out} == {os.getpid()}
    assert seen == [(i, 5) for i in range(1, 6)]


def test_process_pool_runs_in_other_processes_in_order():
    out = parallel_map(_square_and_pid, list(range(12)), jobs=2)
    assert [v for v, _ in out] == [x * x for x in range(12)]
    assert os.getpid() not in {pid for _, pid in out}


def test_errors_propagate_from_the_pool():
    with pytest.raises(ValueError, match="item 3 is bad"):
        parallel_map(_fails_on_three, range(6), jobs=2)


def test_empty_and_bad_arguments():
    assert parallel_map(_square_and_pid, [], jobs=2) == []
    with pytest.raises(ConfigError, match="at least 1"):
        parallel_map(_square_and_pid, [1], jobs=0)
    assert default_jobs(1) == 1 and default_jobs(10_000) >= 1


@pytest.fixture(scope="module")
def dask_client():
    with in_process_cluster() as client:
        yield client


def test_dask_cluster_by_client_and_by_address(dask_client):
    out = parallel_map(_square_on_worker, list(range(8)), scheduler=dask_client)
    assert [v for v, _ in out] == [x * x for x in range(8)]
    workers = set(dask_client.scheduler_info()["workers"])
    assert {w for _, w in out} <= workers  # every item ran on a worker of the cluster
    address = dask_client.scheduler.address
    assert address.startswith("tcp://127.0.0.1:")
    seen = []
    out = parallel_map(_square_on_worker, [3, 1, 2], scheduler=address, progress=lambda d, n: seen.append(d))
    assert [v for v, _ in out] == [9, 1, 4]
    assert sorted(seen) == [1, 2, 3]


def test_dask_errors_propagate(dask_client):
    with pytest.raises(ValueError, match="item 3 is bad"):
        parallel_map(_fails_on_three, range(6), scheduler=dask_client)


def test_unreachable_scheduler_is_one_line(monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr("analysis.parallel.DASK_CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(ConfigError, match="--scheduler"):
        parallel_map(_square_and_pid, [1], scheduler="tcp://127.0.0.1:9")
