"""The cheap forms of the identifiability decisions and of the noise check give the same answers
as the direct ones: the gauge test by a blocked QR (R only) against the SVD of the tall dense
block, the chi-square p-value by ``scipy.special.chdtrc`` against ``scipy.stats``, a fit that
reuses the solver's last Jacobian (and hands the decision's to the solve) against one that
computes every Jacobian again, and the held directions checked one Gauss-Newton step from the
start (one solve) against a decision taken at a solution (two solves)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.special import chdtrc
from scipy.stats import chi2

from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.fit import fit_rounds
from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit.identification import identify
from aacmm_pin.fit.solver import Problem, WarmStart
from aacmm_pin.fit.unknowns import BlockJacobian


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
def layout(sim_400, cal_400):
    """The proposed model's layout and data Jacobian at the start of a paper-sized campaign."""
    sim, cal = sim_400, cal_400
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
    solve = Problem.solve

    def without_jacobians(self, start, *a, **kw):
        # no Jacobian handed in, none handed back: every Jacobian is computed
        if isinstance(start, WarmStart):
            start = dataclasses.replace(start, jacobian=None)
        return dataclasses.replace(solve(self, start, *a, **kw), jacobian=None)

    monkeypatch.setattr(Problem, "solve", without_jacobians)
    again = identify(sim.campaign, arm)
    assert np.array_equal(again.x, cal.x)
    assert np.array_equal(again.covariance, cal.covariance)
    assert again.unidentifiable == cal.unidentifiable


def test_held_directions_are_decided_where_a_gauss_newton_step_lands(arm, monkeypatch):
    """The nominal tool sits on the A7 axis: there, directions mixing dth60 and a76 are
    degenerate, while the simulated tool is 0.16 mm off the axis and 400 samples at 0.2 um noise
    determine them (the singular values in sigmas grow as sqrt(N) / sigma: as 40,000 samples at
    the R-Test's 2 um). Decided at the start, they were held in a first solve and freed in a
    second; decided one Gauss-Newton step from the start, the first solve is the last, and its
    result is the one whose decision was taken at a solution (the rule before, two solves).
    Tolerances: a thousandth of the uncertainty, of the noise, of a plausible size (a plausible
    change along a held direction moves the data by less than 2 sigma)."""
    noise = 0.2e-6
    sim = simulate_campaign(arm, SimulationConfig(seed=1, samples_per_location=100,
                                                  sigma_rtest=noise))
    solves: list[int] = []
    solve = Problem.solve
    monkeypatch.setattr(Problem, "solve", lambda self, *a, **kw: solves.append(1) or
                        solve(self, *a, **kw))
    cal = identify(sim.campaign, arm, sigma=noise)
    assert len(solves) == 1
    # the rule before: decided at the start, checked at the solution, decided again there
    monkeypatch.setattr(fit_rounds, "decision_point",
                        lambda problem, jac0, on_evaluation, *_: (np.zeros(problem.p.shape[1]),
                                                                  None, 0))
    ref = identify(sim.campaign, arm, sigma=noise)
    assert len(solves) == 1 + 2  # the start holds what the solution determines
    assert cal.constraints.shape[0] == ref.constraints.shape[0]
    n_arm = len(ref.unknowns.names)
    std = np.sqrt(np.diag(ref.covariance))
    seen = np.concatenate([ref.identifiable, np.ones(std.size - n_arm, bool)])
    # identifiable entries to a thousandth of their uncertainty, the fit to a thousandth of the
    # noise, the entries not identifiable to a thousandth of their plausible size
    np.testing.assert_array_less(np.abs(cal.x - ref.x)[seen], 1e-3 * std[seen])
    assert np.sqrt(np.mean((cal.fun - ref.fun) ** 2)) < 1e-3 * noise
    scale = ident.plausible_sizes(ref.unknowns)[ref.unknowns.free]
    np.testing.assert_array_less(np.abs(cal.x - ref.x)[:n_arm][~ref.identifiable],
                                 1e-3 * scale[~ref.identifiable])
