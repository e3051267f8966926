"""The execution layer of batch analysis: map one function over many items (recordings, campaign directories,
self-check trials) on a local process pool by default, or on a Dask cluster when given a scheduler address.

    from analysis.parallel import parallel_map
    results = parallel_map(fit_one, paths)                          # local processes (one per core)
    results = parallel_map(fit_one, paths, jobs=1)                  # in this process (debugging, tiny batches)
    results = parallel_map(fit_one, paths, scheduler="tcp://10.0.0.5:8786")   # a Dask cluster

Results come back in the order of `items`, whatever order the workers finish in. The first exception raised by
`fn` is re-raised here (the remaining items are cancelled). `fn` must be importable by the workers: a module-level
function, not a lambda or a closure (the process pool and Dask both pickle it by name), and its items and result
must pickle. On Dask the workers need this package installed (the same version): they import `fn`'s module.

Dask is an optional extra (`pip install 'hamr-bench[dask]'`); only the scheduler path imports it, and a missing
install is a one-line ConfigError naming the extra.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from hamr_bench.errors import ConfigError

T = TypeVar("T")
R = TypeVar("R")

DASK_EXTRA_HINT = "pip install 'hamr-bench[dask]' (or: pip install 'dask[distributed]')"
DASK_CONNECT_TIMEOUT_S = 10.0


def default_jobs(n_items: int) -> int:
    """Local workers for `n_items`: one per core available to this process, never more than the items."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, n_items))


def one_blas_thread() -> None:
    """A worker process's initializer: its linear algebra on one thread. Each worker is one of `jobs` processes
    on as many cores; numpy's and scipy's BLAS start a thread per core each on top, and the processes then crawl
    (the gap diagnosis of the five-effect campaign with two workers: 74 s that way, 56 s with this;
    docs/performance.md)."""
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    threadpool_limits(limits=1)


def parallel_map(
    fn: Callable[[T], R],
    items: Iterable[T],
    *,
    jobs: int | None = None,
    scheduler: str | Any | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[R]:
    """`[fn(item) for item in items]`, spread over workers; see the module docstring.

    jobs: local worker processes (default: one per core, at most one per item; 1 runs in this process).
    scheduler: a Dask scheduler address ("tcp://HOST:8786") or an existing `distributed.Client`; when given,
        `jobs` is ignored (the cluster decides).
    progress: called as progress(done, total) after each item finishes (in completion order).
    """
    work = list(items)
    if jobs is not None and jobs < 1:
        raise ConfigError(f"--jobs: expected at least 1 worker, got {jobs}")
    if not work:
        return []
    if scheduler is not None:
        return _dask_map(fn, work, scheduler, progress)
    n_jobs = default_jobs(len(work)) if jobs is None else min(jobs, len(work))
    if n_jobs == 1:
        out = []
        for i, item in enumerate(work):
            out.append(fn(item))
            if progress:
                progress(i + 1, len(work))
        return out
    with ProcessPoolExecutor(max_workers=n_jobs, initializer=one_blas_thread) as pool:
        futures = [pool.submit(fn, item) for item in work]
        return _gather_in_order(futures, progress)


def _gather_in_order(futures: list, progress: Callable[[int, int], None] | None) -> list:
    from concurrent.futures import FIRST_EXCEPTION, wait

    pending = set(futures)
    done_count = 0
    while pending:
        done, pending = wait(pending, return_when=FIRST_EXCEPTION)
        for future in done:
            error = future.exception()
            if error is not None:
                for other in pending:
                    other.cancel()
                raise error
            done_count += 1
            if progress:
                progress(done_count, len(futures))
    return [f.result() for f in futures]


def _dask_client(scheduler: str | Any) -> tuple[Any, bool]:
    """(client, owned): a Client connected to `scheduler`, or the Client given (not closed by us)."""
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(f"--scheduler needs Dask, which is not installed: {DASK_EXTRA_HINT}") from None
    if isinstance(scheduler, Client):
        return scheduler, False
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise ConfigError(f"--scheduler: expected an address such as tcp://HOST:8786, got {scheduler!r}")
    try:
        return Client(scheduler.strip(), timeout=f"{DASK_CONNECT_TIMEOUT_S}s"), True
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler ({exc})") from None


def _dask_map(fn: Callable, work: list, scheduler: str | Any, progress: Callable[[int, int], None] | None) -> list:
    from distributed import as_completed

    client, owned = _dask_client(scheduler)
    try:
        # pure=False: two equal items (the same recording given twice) are still two tasks.
        futures = client.map(fn, work, pure=False)
        done_count = 0
        try:
            for future in as_completed(futures):
                if future.status == "error":
                    raise future.exception()
                done_count += 1
                if progress:
                    progress(done_count, len(work))
        except BaseException:
            client.cancel(futures)
            raise
        return client.gather(futures)
    finally:
        if owned:
            client.close()
