"""Candidate fits side by side: screening fits every candidate alone on the nominal fit, and each selection step
fits every promising candidate on the effects named so far; those fits are independent of each other, so with
`jobs` > 1 they run in worker processes (each on one BLAS thread), the slowest first. The workers are forked once
the problem is built and inherit it (nothing large is sent to them); each returns its `Fit`. The fits are the same
numbers as in one process (a fit depends on its start and the data only; a fit made in this process runs on one
BLAS thread too, as the workers' do: a thread count changes an SVD's last digits, and a fit stopped at its
evaluation limit carries them on), so the diagnosis does not depend on `jobs`. A selection step's fits also get
their held-out z in the worker (`add_each_judged`: the judge's folds are the problem's, inherited the same way),
which the main process would otherwise compute one fit after another while the workers wait. Where fork is not
available (Windows, macOS by default) the fits run in this process."""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from analysis.gap.heldout import Judge
from analysis.gap.problem import Fit, Problem
from analysis.gap.screening import Start, add_each_here, add_onto_here, fit_added, grid_objectives_here
from analysis.parallel import one_blas_thread

_PROBLEM: Problem | None = None      # the problem a forked worker inherited
_JUDGE: Judge | None = None          # and its held-out judge


def _add_one(task: tuple[Fit, str, Start | None, int, bool]) -> tuple[Fit, float]:
    base, name, start, max_nfev, judged = task
    assert _PROBLEM is not None  # set before the workers were forked
    t0 = time.perf_counter()
    fit = fit_added(_PROBLEM, base, name, start, max_nfev)
    if judged and _JUDGE is not None:
        _JUDGE.z(fit)            # kept in fit.extra, returned with the fit
    return fit, time.perf_counter() - t0


def _grid_one(task: tuple[Fit, str]) -> float:
    base, name = task
    assert _PROBLEM is not None  # set before the workers were forked
    return grid_objectives_here(_PROBLEM)(base, [name])[name]


class FitPool:
    """`add_each(base, names, max_nfev, starts)`: `screening.AddEach`, its fits side by side (each of a name's
    starts a task of its own)."""

    def __init__(self, p: Problem, jobs: int = 1, judge: Judge | None = None) -> None:
        self.p = p
        self._pool: Any = None
        self._took: dict[str, float] = {}     # candidate -> how long its last fit took (s)
        if jobs > 1 and "fork" in multiprocessing.get_all_start_methods():
            global _PROBLEM, _JUDGE
            _PROBLEM, _JUDGE = p, judge
            self._pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("fork"),
                                             initializer=one_blas_thread)

    def add_each(self, base: Fit, names: Sequence[str], max_nfev: int,
                 starts: Mapping[str, Sequence[Start | None]] | None = None, looks: Sequence[str] = (),
                 look_nfev: int = 0) -> dict[str, Fit]:
        return self._add_each(base, names, max_nfev, starts or {}, False, looks, look_nfev)

    def add_each_judged(self, base: Fit, names: Sequence[str], max_nfev: int,
                        starts: Mapping[str, Sequence[Start | None]] | None = None, looks: Sequence[str] = (),
                        look_nfev: int = 0) -> dict[str, Fit]:
        """`add_each`, each full fit returned with its held-out z (a selection step judges every fit it makes; a
        look is judged only if it passes, as a fit of its own)."""
        return self._add_each(base, names, max_nfev, starts or {}, True, looks, look_nfev)

    def _add_each(self, base: Fit, names: Sequence[str], max_nfev: int,
                  starts: Mapping[str, Sequence[Start | None]], judged: bool, looks: Sequence[str],
                  look_nfev: int) -> dict[str, Fit]:
        tasks = [(n, s0, max_nfev, judged) for n in names for s0 in starts.get(n, [None])]
        tasks += [(n, None, look_nfev, False) for n in looks]
        if self._pool is None or len(tasks) < 2:
            with threadpool_limits(limits=1):
                return add_each_here(self.p)(base, names, max_nfev, starts, looks, look_nfev)
        # longest first (by what each candidate's last fit took; a new one counts as longest): the step waits for
        # its slowest fit, so that one should not start last
        tasks.sort(key=lambda t: -self._took.get(t[0], math.inf))
        out: dict[str, Fit] = {}
        done = self._pool.map(_add_one, [(base, n, s0, nfev, j) for n, s0, nfev, j in tasks])
        for (n, _, nfev, _), (fit, took) in zip(tasks, done, strict=True):
            if nfev == max_nfev:     # a short look's time says little about the candidate's full fit
                self._took[n] = took
            if n not in out or fit.objective < out[n].objective:
                out[n] = fit
        return {n: out[n] for n in (*names, *looks)}

    def add_onto(self, tasks: Sequence[tuple[Fit, str, Start]], max_nfev: int) -> list[Fit]:
        """`screening.AddOnto`: each task's name added to its own base, side by side, each fit with its held-out
        z (`joint_entry`'s pairs)."""
        if self._pool is None or len(tasks) < 2:
            with threadpool_limits(limits=1):
                return add_onto_here(self.p)(tasks, max_nfev)
        done = self._pool.map(_add_one, [(base, n, s0, max_nfev, True) for base, n, s0 in tasks])
        return [fit for fit, _ in done]

    def grid_objectives(self, base: Fit, names: Sequence[str]) -> dict[str, float]:
        """Each candidate's best objective on its coarse grid added to `base` (`screening.grid_best`)."""
        if self._pool is None or len(names) < 2:
            with threadpool_limits(limits=1):
                return grid_objectives_here(self.p)(base, names)
        return dict(zip(names, self._pool.map(_grid_one, [(base, n) for n in names]), strict=True))

    def close(self) -> None:
        global _PROBLEM, _JUDGE
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
            _PROBLEM, _JUDGE = None, None

    def __enter__(self) -> FitPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
