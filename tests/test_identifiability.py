"""The cheap forms of the identifiability decisions and of the noise check give the same answers
as the direct ones: the gauge test by a blocked QR (R only) against the SVD of the tall dense
block, the chi-square p-value by ``scipy.special.chdtrc`` against ``scipy.stats``, and a fit that
reuses the solver's last Jacobian against one that computes every Jacobian again."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import chdtrc
from scipy.stats import chi2

from aacmm_pin import identifiability as ident
from aacmm_pin.identification import identify
from aacmm_pin.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.solver import Problem
from aacmm_pin.unknowns import BlockJacobian


def _svd_gauge_ratios(unknowns, jac) -> dict[int, float]:
    """Per map axis: relative residual of its constant column off the dense block's range (SVD)."""
    full_cols = np.flatnonzero(unknowns.free)
    u, sv, _ = np.linalg.svd(jac.dense, full_matrices=False)
    rng = u[:, sv > sv.max() * np.finfo(float).eps * max(jac.dense.shape)]
    out = {}
    for axis in unknowns.map_axes:
        sl = unknowns.map_slice(axis)
        cols = np.flatnonzero((full_cols >= sl.start) & (full_cols < sl.stop))
        if cols.size:
            c = jac.columns_sum(cols)
            out[axis] = float(np.linalg.norm(c - rng @ (rng.T @ c)) / np.linalg.norm(c))
    return out


@pytest.fixture(scope="module")
def layout(arm):
    """The proposed model's layout and data Jacobian at the start of a paper-sized campaign."""
    sim = simulate_campaign(arm, SimulationConfig(seed=2, samples_per_location=100))
    cal = identify(sim.campaign, arm)
    unknowns = cal.unknowns
    _, jac = unknowns.jacobian(unknowns.vector(cal.parameters), cal.q)
    return sim, cal, unknowns, jac


def test_gauge_axes_match_the_svd_of_the_dense_block(layout, monkeypatch):
    _, _, unknowns, jac = layout
    # without dth30's column (noise instead) the A3 map's constant leaves the dense block's span
    dense = jac.dense.copy()
    dense[:, unknowns.names.index("dth30")] = np.random.default_rng(0).normal(size=len(dense))
    for block in (jac, BlockJacobian(dense, jac.axes, jac.n_nodes)):
        ratios = _svd_gauge_ratios(unknowns, block)
        assert all(r > 1e3 * ident.GAUGE_TOL or r < 1e-3 * ident.GAUGE_TOL for r in ratios.values())
        expected = [a for a, r in ratios.items() if r < ident.GAUGE_TOL]
        assert ident.gauge_axes(unknowns, block) == expected
        with monkeypatch.context() as m:
            m.setattr(ident, "QR_ROWS", 97)  # many blocks, the last one short
            assert ident.gauge_axes(unknowns, block) == expected
    assert 3 in ident.gauge_axes(unknowns, jac)
    assert 3 not in expected


def test_noise_p_value_is_scipy_stats_chi2():
    rng = np.random.default_rng(0)
    for dof in (1, 2, 7, 100, 4_800, 480_000):
        for stat in dof * rng.uniform(0.5, 1.5, 5):
            assert chdtrc(dof, stat) == chi2.sf(stat, dof)


def test_reused_jacobians_change_nothing(arm, layout, monkeypatch):
    sim, cal, _, _ = layout
    monkeypatch.setattr(Problem, "take_jacobian", lambda self, z: None)
    again = identify(sim.campaign, arm)
    assert np.array_equal(again.x, cal.x)
    assert np.array_equal(again.covariance, cal.covariance)
    assert again.unidentifiable == cal.unidentifiable
