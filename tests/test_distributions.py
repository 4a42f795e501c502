"""aacmm_pin.distributions against scipy.stats: the same value for every input, edges included."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from aacmm_pin import distributions as d

XS = (-1.0, 0.0, 1e-300, 1e-8, 0.3, 1.0, 2.5, 7.0, 40.0, 1e3, 1e9, math.inf, -math.inf, math.nan)
PS = (-0.1, 0.0, 1e-300, 1e-12, 1e-3, 0.05, 0.5, 0.99, 1 - 1e-12, 1.0, 1.1, math.nan)
DOFS = (-1.0, 0.0, 0.5, 1.0, 3.0, 17.0, 2975.0, 1e6, math.nan)


def _same(ours: float, theirs: float) -> None:
    assert isinstance(ours, float)
    np.testing.assert_array_equal(ours, float(theirs))  # nan == nan; bit for bit otherwise


@pytest.mark.parametrize("dof", DOFS)
def test_chi2_as_scipy_stats(dof: float) -> None:
    for x in XS:
        _same(d.chi2_sf(x, dof), stats.chi2.sf(x, dof))
    for p in PS:
        _same(d.chi2_isf(p, dof), stats.chi2.isf(p, dof))
        _same(d.chi2_ppf(p, dof), stats.chi2.ppf(p, dof))


@pytest.mark.parametrize("dfn", DOFS)
def test_f_as_scipy_stats(dfn: float) -> None:
    with np.errstate(divide="ignore"):
        for x, dfd in itertools.product(XS, DOFS):
            _same(d.f_sf(x, dfn, dfd), stats.f.sf(x, dfn, dfd))
            _same(d.f_logsf(x, dfn, dfd), stats.f.logsf(x, dfn, dfd))


def test_tails_are_probabilities() -> None:
    """The tails fall with x and invert each other (a check that does not lean on scipy.stats)."""
    xs = np.linspace(0.01, 30, 50)
    sf = [d.chi2_sf(float(x), 4.0) for x in xs]
    assert all(a > b for a, b in itertools.pairwise(sf))
    for p in (1e-6, 0.01, 0.5, 0.9):
        assert d.chi2_sf(d.chi2_isf(p, 4.0), 4.0) == pytest.approx(p, rel=1e-10)
        assert d.chi2_ppf(1 - p, 4.0) == pytest.approx(d.chi2_isf(p, 4.0), rel=1e-8)
    assert d.chi2_sf(2.0, 2.0) == pytest.approx(math.exp(-1.0), rel=1e-14)  # 2 dof: exp(-x/2)
    assert d.f_sf(1.0, 2.0, 2.0) == pytest.approx(0.5, rel=1e-14)  # F(2, 2): 1 / (1 + x)


def test_bartlett_as_scipy_stats() -> None:
    rng = np.random.default_rng(3)
    for k in (2, 3, 5):
        for scale in (1.0, 1.3):
            groups = [rng.normal(0, scale ** i, rng.integers(2, 400)) for i in range(k)]
            _same(d.bartlett_p(groups), stats.bartlett(*groups).pvalue)
    same = [rng.normal(0, 1, 10_000) for _ in range(4)]
    wide = [*same[:3], 1.1 * same[3]]
    assert d.bartlett_p(same) > 1e-3 > d.bartlett_p(wide)  # equal spreads pass, 10 % wider fails
