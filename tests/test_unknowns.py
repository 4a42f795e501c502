"""The Jacobians the solver uses, against central differences: the unknowns' block Jacobian (DH
model, map nodes, extension terms) and the reduced, preconditioned problem of :func:`identify`.

Step sizes and tolerances. Every entry is measured in *angle-equivalent* units: 1 for the arm's
own entries (rad for X0, DH angles and map nodes; m for translations, which enter linearly), and
for an extension parameter the largest value of its basis over the samples (N m of gravity torque
per rad/(N m) of compliance, K per 1/K of thermal expansion, m of R-Test displacement per unit
gain): one unit of the entry turns an axis by at most that many rad, scales lengths by that much or
moves the measured point by that many m. A step of H = 1e-5 angle-equivalent then has

* truncation error h^2 |p'''| / 6 <= (1e-5)^2 x 1.5 m / 6 ~ 3e-11 m per unit (|p'''| is bounded by
  the stylus' distance from the axes, < 1.5 m in the MT-CS);
* rounding error ~ 10 eps |p| / h = 10 x 2.2e-16 x 1.5 m / 1e-5 ~ 3e-10 m per unit (a position is
  a chain of a few tens of floating-point products, |p| < 1.5 m).

ATOL = 1e-8 m per angle-equivalent unit bounds both with a margin of 30 (measured: 3e-11). A wrong
column is off by O(its size): the smallest non-zero one here is 2e-6 m per unit (a map node that a
sample barely reaches), 180 x ATOL.
"""

from __future__ import annotations

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin import effects as fx
from aacmm_pin.fit.unknowns import Unknowns
from aacmm_pin.model.samples import Samples
from tests.helpers import central_differences

H, ATOL = 1e-5, 1e-8
TERMS = (fx.compliance(2), fx.thermal(), fx.rtest(), fx.backlash(3))
AXES = tuple(range(1, 8))


def _units(u: Unknowns) -> np.ndarray:
    """Angle-equivalent size of one unit of every free entry (see the module docstring)."""
    full = np.ones(u.free.size)
    at = u.n_dense - u.n_terms
    for term in u.terms:
        basis = np.abs(term.basis(u.samples))
        per_parameter = basis.reshape(-1, basis.shape[-1]).max(axis=0)
        full[at:at + per_parameter.size] = per_parameter
        at += per_parameter.size
    return full[u.free]


@pytest.fixture(scope="module")
def layouts(arm: ap.Arm, effects_sim: ap.Simulation) -> dict[str, tuple[Unknowns, np.ndarray]]:
    """The DH, the proposed (maps, some entries held) and the extended layouts, at the truth."""
    samples = Samples.of_spat(arm, effects_sim.campaign.spat)
    rng = np.random.default_rng(0)
    ext = {t.key: rng.normal(0.0, 1.0, len(t.names)) * np.array(t.plausible) for t in TERMS}
    plain = effects_sim.truth  # DH errors, tool and maps all non-zero
    params = plain.replace(extensions=ext)
    dh = Unknowns.full(arm, plain, ())
    proposed = Unknowns.full(arm, plain, AXES)
    held = rng.random(proposed.free.size) < 0.2  # the free mask must pick the right columns
    proposed = proposed.with_fixed(held)
    extended = Unknowns.full(arm, params, AXES, TERMS, samples)
    return {name: (u, u.vector(u.start)) for name, u in
            (("dh", dh), ("proposed", proposed), ("extended", extended))}


@pytest.fixture(scope="module", params=["dh", "proposed", "extended"])
def case(request, layouts, effects_sim: ap.Simulation):
    """One layout, its point x, the readouts, the analytic Jacobian and its central differences."""
    u, x = layouts[request.param]
    q = u.samples.q if u.samples is not None else effects_sim.campaign.spat.q
    units = _units(u)
    positions, jac = u.jacobian(x, q)
    fd = central_differences(lambda v: u.positions(v, q), x, H / units)
    return u, x, q, units, positions, jac, fd


def test_layouts_have_the_expected_columns(layouts) -> None:
    """The cases cover what they claim: DH only, map nodes with held entries, extension terms."""
    dh, proposed, extended = (layouts[k][0] for k in ("dh", "proposed", "extended"))
    assert dh.free.sum() == 6 + 22 + 3
    assert 0 < proposed.free.sum() < proposed.free.size and proposed.n_terms == 0
    assert extended.n_terms == 1 + 1 + 3 + 1 and extended.free.all()


def test_positions_of_the_jacobian_are_the_model_positions(case) -> None:
    """jacobian(x, q) returns positions(x, q) with it (two Pinocchio paths, same numbers)."""
    u, x, q, _, positions, _, _ = case
    np.testing.assert_allclose(positions, u.positions(x, q), rtol=0, atol=1e-12)


def test_sparse_jacobian_equals_central_differences(case) -> None:
    """Every column of BlockJacobian.sparse() matches central differences of positions."""
    u, _, _, units, _, jac, fd = case
    analytic = jac.sparse().toarray()
    assert analytic.shape == fd.shape == (fd.shape[0], int(u.free.sum()))
    # per column, in m per angle-equivalent unit
    np.testing.assert_allclose(analytic / units, fd / units, rtol=0, atol=ATOL)
    assert np.abs(fd / units).max() > 0.1  # the check is not vacuous


def test_matmul_equals_central_differences(case) -> None:
    """J @ M (a matrix and a vector) matches the differences' J @ M within the propagated bound."""
    _, _, _, units, _, jac, fd = case
    rng = np.random.default_rng(1)
    m = rng.normal(size=(units.size, 3)) / units[:, None]  # O(1) angle-equivalent per entry
    bound = ATOL * (units[:, None] * np.abs(m)).sum(axis=0)  # sum_j |error of column j| |M_jk|
    assert np.all(np.abs(jac.matmul(m) - fd @ m) <= bound)
    v = m[:, 0]
    assert np.all(np.abs(jac.matmul(v) - fd @ v) <= bound[0])


def test_rmatmul_equals_central_differences(case) -> None:
    """J^T @ u matches the differences' J^T @ u within the propagated bound."""
    _, _, _, units, _, jac, fd = case
    w = np.random.default_rng(2).normal(size=fd.shape[0])
    bound = ATOL * units * np.abs(w).sum()  # |error of column j| sum_i |w_i|
    assert np.all(np.abs(jac.rmatmul(w) - fd.T @ w) <= bound)


def test_normal_matrix_equals_central_differences(case) -> None:
    """J^T J from the block products matches the differences' J^T J within the propagated bound."""
    _, _, _, units, _, jac, fd = case
    delta = ATOL * units  # error bound of each column of fd
    colsum = (np.abs(fd) + delta).sum(axis=0)  # bounds sum_i |J_ij| of the true Jacobian
    # (J + E)^T (J + E) - J^T J = J^T E + E^T J + E^T E, with |E_ij| <= delta_j
    bound = (delta[:, None] * colsum[None, :] + colsum[:, None] * delta[None, :]
             + fd.shape[0] * delta[:, None] * delta[None, :])
    assert np.all(np.abs(jac.normal() - fd.T @ fd) <= bound)


def test_structured_products_equal_the_sparse_matrix(case) -> None:
    """The map-node products from the per-sample structure (two nodes per axis and sample) equal
    those of the assembled sparse Jacobian, weighted rows included (to rounding)."""
    _, _, _, _, _, jac, _ = case
    rng = np.random.default_rng(3)
    weights = rng.uniform(0.5, 2.0, jac.shape[0])
    for j in (jac, jac.scaled(weights)):
        full = j.sparse().toarray()
        scale = np.abs(full).max()
        u = rng.normal(size=(full.shape[0], 4))
        np.testing.assert_allclose(j.normal(), full.T @ full, rtol=0, atol=1e-12 * scale ** 2
                                   * full.shape[0])
        np.testing.assert_allclose(j.node_rmatmul(u), full[:, j.dense.shape[1]:].T @ u, rtol=0,
                                   atol=1e-12 * scale * full.shape[0])
        cols = np.flatnonzero(rng.random(full.shape[1]) < 0.3)
        np.testing.assert_allclose(j.columns_sum(cols), full[:, cols].sum(axis=1), rtol=0,
                                   atol=1e-12 * scale)
        np.testing.assert_array_equal(j.nodes.toarray(), full[:, j.dense.shape[1]:])


# ---------------------------------------------------------------- the solver's problem
@pytest.fixture(scope="module", params=["dh", "proposed", "extended"])
def problem_case(request, arm: ap.Arm, effects_sim: ap.Simulation):
    """A calibration of the small campaign and the angle-equivalent size of each reduced entry."""
    model, terms = {"dh": ("dh", ()), "proposed": ("proposed", ()),
                    "extended": ("proposed", (fx.compliance(2), fx.thermal(), fx.rtest()))
                    }[request.param]
    cal = ap.identify(effects_sim.campaign, arm, model=model, extensions=terms)
    problem = cal.problem
    units = np.concatenate([_units(problem.unknowns), np.ones(problem.n_loc)])  # nest offsets in m
    # one unit of z_k moves the full vector by P[:, k]: by sum_j |P_jk| units_j angle-equivalent
    size = (np.abs(problem.p) * units[:, None]).sum(axis=0)
    return cal, problem, size


@pytest.mark.parametrize("where", ["solution", "perturbed"])
def test_problem_jacobian_equals_central_differences(problem_case, where: str) -> None:
    """jac(z) (dense) and jac_operator(z) (a LinearOperator) match central differences of fun, at
    the solution and away from it.

    A step h_k = H / size_k along z_k moves the arm entries by at most H angle-equivalent in all,
    so the error of column k is bounded by ATOL x size_k (module docstring); the nests' prior rows
    are linear.
    """
    cal, problem, size = problem_case
    z = problem.z(cal.x)
    # z(x) is a least-squares solve with P: its round trip is exact to eps x cond(P) x |x|
    bound = np.finfo(float).eps * np.linalg.cond(problem.p) * np.abs(cal.x).max()
    np.testing.assert_allclose(problem.x(z), cal.x, rtol=0, atol=bound)
    if where == "perturbed":
        rng = np.random.default_rng(3)
        z = z + rng.normal(size=z.size) * 1e-4 / size  # ~1e-4 rad-equivalent along every z_k
    fd = central_differences(problem.fun, z, H / size)
    delta = ATOL * size
    dense = problem.jac(z)
    assert isinstance(dense, np.ndarray) and dense.shape == fd.shape
    np.testing.assert_allclose(dense / size, fd / size, rtol=0, atol=ATOL)
    op = problem.jac_operator(z)
    assert op.shape == fd.shape
    np.testing.assert_allclose(op.matmat(np.eye(z.size)) / size, fd / size, rtol=0, atol=ATOL)
    np.testing.assert_allclose(op.rmatmat(np.eye(fd.shape[0])).T / size, fd / size, rtol=0,
                               atol=ATOL)
    rng = np.random.default_rng(4)
    v, w = rng.normal(size=z.size), rng.normal(size=fd.shape[0])
    assert np.all(np.abs(op.matvec(v) - fd @ v) <= (delta * np.abs(v)).sum())
    assert np.all(np.abs(op.rmatvec(w) - fd.T @ w) <= delta * np.abs(w).sum())
