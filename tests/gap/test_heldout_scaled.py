"""The held-out refit's pseudo-inverse is taken in the parameters' scaled units (`Layout.scales`), so what the
judge says does not depend on the units a parameter is written in. A nuisance the training rows barely see (a lag
whose column holds only finite-difference noise outside the left-out condition) sits near the cut; in raw units a
parameter written in metres or seconds decides by its unit whether it is cut, and one kept took a step of 10^6 of
its size that turned the noise in its column into held-out errors of 10^3 noise units (the five-effect campaign's
specimen folds)."""

from __future__ import annotations

import numpy as np

from analysis.gap.heldout import heldout_errors
from analysis.gap.problem import Fit, Layout, Param


def _fit(unit: float) -> tuple[Fit, list[np.ndarray]]:
    """A linear fit of 60 rows and 4 parameters; the last one is written in `unit` (its column / unit, its scale
    x unit), seen by the first fold's rows and, elsewhere, only at the 1e-13 level (finite-difference noise)."""
    rng = np.random.default_rng(7)
    n = 60
    jac = rng.normal(size=(n, 4))
    held = np.zeros(n, bool)
    held[:12] = True
    jac[~held, 3] = rng.normal(scale=1e-13, size=(~held).sum())
    jac[:, 3] /= unit
    residual = rng.normal(size=n)
    params = [Param("gain", (str(i),), -1.0, 1.0, 0.05, 0.0) for i in range(3)] + \
        [Param("lag", ("chain",), -1.0, 1.0, 5e-3 * unit, 0.0)]
    lay = Layout((), params, {}, n, 0)
    return Fit((), lay, np.zeros(4), residual, jac, {}), [held, ~held & (np.arange(n) % 2 == 0)]


def test_held_out_errors_do_not_depend_on_a_parameters_unit():
    reference, folds = _fit(1.0)
    e0, s0, steps0 = heldout_errors(reference, folds)
    for unit in (1e-6, 1e3):
        fit, _ = _fit(unit)
        e, s, steps = heldout_errors(fit, folds)
        np.testing.assert_allclose(e, e0, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(s, s0, rtol=1e-7)
        for a, b in zip(steps, steps0, strict=True):
            np.testing.assert_allclose(a[:3], b[:3], rtol=1e-6, atol=1e-12)
            np.testing.assert_allclose(a[3] / unit, b[3], rtol=1e-6, atol=1e-12)
    # and the nearly unseen lag does not blow up the first fold's prediction
    assert np.sqrt(np.mean(e0[folds[0]] ** 2)) < 10.0


def test_a_fits_covariance_does_not_depend_on_a_parameters_unit():
    """Down to a unit that makes the parameter's column 10^-11 of the others (a strength in N/sqrt(s) against a
    contact shift per metre is further apart than that): in raw units that direction fell below the cut and its
    variance came out 0."""
    reference, _ = _fit(1.0)
    for unit in (1e-6, 1e3, 1e11):
        fit, _ = _fit(unit)
        scaled = fit.covariance() / np.outer([1, 1, 1, unit], [1, 1, 1, unit])
        np.testing.assert_allclose(scaled, reference.covariance(), rtol=1e-6, atol=1e-12)
