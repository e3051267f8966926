"""Where the candidate fits run: a fit made in the pool's own process (one process, or a step with a single fit)
runs its linear algebra on one BLAS thread, as the forked workers' do, so its last digits, and a fit stopped at
its evaluation limit with them, do not depend on `jobs`."""

from threadpoolctl import threadpool_info  # type: ignore[import-untyped]

import analysis.gap.fitpool as fitpool
from analysis.gap.fitpool import FitPool


def _blas_threads() -> set[int]:
    return {int(lib["num_threads"]) for lib in threadpool_info() if lib.get("user_api") == "blas"}


def test_a_fit_in_the_pools_own_process_runs_on_one_blas_thread(monkeypatch):
    seen: list[set[int]] = []

    def stand_in(_p):
        def run(*_args):
            seen.append(_blas_threads())
            return {}
        return run

    for name in ("add_each_here", "add_onto_here", "grid_objectives_here"):
        monkeypatch.setattr(fitpool, name, stand_in)
    with FitPool(object(), jobs=1) as pool:         # type: ignore[arg-type]
        pool.add_each(object(), ["creep"], 40)       # type: ignore[arg-type]
        pool.add_each_judged(object(), ["creep"], 40)    # type: ignore[arg-type]
        pool.add_onto([], 40)
        pool.grid_objectives(object(), ["creep"])    # type: ignore[arg-type]
    assert len(seen) == 4
    assert all(threads == {1} for threads in seen), seen
