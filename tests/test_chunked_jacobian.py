"""A large campaign's Jacobian is never held whole (issue 28): its products taken chunk by chunk.

Above :data:`~aacmm_pin.fit.chunked_jacobian.CHUNKED_BYTES` the fit takes J^T J, J^T (nuisance
columns), J^T f and the gauge check's R factor from a
:class:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian`, and the solver's steps from the normal
equations (:meth:`~aacmm_pin.fit.solver.Problem.compressed`). These tests force that route on a
small campaign (the threshold set to 0, chunks of a few hundred samples) and compare it with the
whole Jacobian's.

Tolerances: sums over chunks differ from sums over all rows by rounding only (1e-12 relative, a
few hundred rows summed); two solves that both end on the solver's step tolerance
(:data:`~aacmm_pin.fit.solver.STEP_TOL`, 1e-4 standard deviations per reduced coordinate) agree
within a few times that, so the determined entries are compared at 1e-3 of their standard
deviations (entries the data do not determine, standard deviation below 1e-12, are held and
compared by value).
"""

from __future__ import annotations

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.fit import chunked_jacobian as cj
from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit import unknowns as unk
from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian
from aacmm_pin.fit.identification import identify


@pytest.fixture(scope="module")
def sim(sim_400: ap.Simulation) -> ap.Simulation:
    """400 SPAT samples (4 locations), DH and encoder errors: a layout from the chain alone."""
    return sim_400


@pytest.fixture(scope="module")
def cal(cal_400: ap.Calibration) -> ap.Calibration:
    """The campaign identified the usual way (the whole Jacobian held)."""
    return cal_400


def _chunked(monkeypatch: pytest.MonkeyPatch, samples: int) -> None:
    monkeypatch.setattr(cj, "CHUNKED_BYTES", 0)
    monkeypatch.setattr(cj, "CHUNK_SAMPLES", samples)


def test_rows_of_a_chunk_are_those_of_the_whole_jacobian(cal: ap.Calibration):
    u, q = cal.unknowns, cal.problem.q
    x = cal.x[:cal.problem.n_arm]
    pos, whole = u.jacobian(x, q)
    lo, hi = 150, 290
    pos_rows, rows = u.jacobian_rows(x, q, lo, hi)
    assert np.array_equal(pos_rows, pos[lo:hi])
    assert np.array_equal(rows.sparse().toarray(), whole.sparse()[3 * lo:3 * hi].toarray())


def test_chunked_positions_are_those_of_one_call(cal: ap.Calibration,
                                                 monkeypatch: pytest.MonkeyPatch):
    u, x = cal.unknowns, cal.x[:cal.problem.n_arm]
    q = np.tile(cal.problem.q, (3, 1))
    whole = u.positions(x, q)
    monkeypatch.setattr(unk, "BUILD_CHUNK", 256)
    assert np.array_equal(u.positions(x, q), whole)


def test_chunked_products_equal_the_whole_jacobians(cal: ap.Calibration,
                                                    monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(cj, "CHUNK_SAMPLES", 128)
    prob = cal.problem
    x = cal.x
    _, whole = cal.unknowns.jacobian(x[:prob.n_arm], prob.q)
    w = np.random.default_rng(0).uniform(0.5, 1.5, prob.n_data)
    whole = whole.scaled(w)
    chunked = ChunkedJacobian(cal.unknowns, x[:prob.n_arm], prob.q, w)
    nuis = prob.nuisance_jacobian(x)
    f = np.random.default_rng(1).normal(size=prob.n_data)
    normal, cross, grad = chunked.products(nuis, f)
    ref = whole.normal()
    scale = np.abs(ref).max()
    assert np.abs(normal - ref).max() < 1e-12 * scale
    assert cross is not None and grad is not None
    assert np.allclose(cross, whole.cross(nuis), rtol=0, atol=1e-12 * np.abs(cross).max())
    assert np.allclose(cj.sparse_cross(whole, nuis), whole.cross(nuis), rtol=0,
                       atol=1e-12 * np.abs(cross).max())
    assert np.allclose(grad, whole.rmatmul(f), rtol=0, atol=1e-12 * np.abs(grad).max())
    m = np.random.default_rng(2).normal(size=whole.shape[1])
    assert np.allclose(chunked.matmul(m), whole.matmul(m), rtol=0, atol=1e-12 * scale)
    # J^T J and the last J^T u are kept: asked again (the covariance at a solve's solution), no pass
    monkeypatch.setattr(chunked, "chunks", lambda: iter(()))
    assert np.array_equal(chunked.normal(), normal)
    assert np.array_equal(chunked.cross(prob.nuisance_jacobian(x)), cross)


def test_compressed_operator_has_the_jacobians_normal_equations(cal: ap.Calibration):
    """K^T K = (J P)^T (J P) and K^T f = (J P)^T f: the least-squares steps are the same."""
    prob = cal.problem
    z = prob.z(cal.x) + 0.3  # away from the solution: f has a component in J's span
    f = prob.fun(z)
    jp = prob.jac(z)
    op, _ = prob.compressed(z, f)
    k = np.column_stack([op.matvec(e) for e in np.eye(jp.shape[1])])
    a = jp.T @ jp
    assert np.abs(k.T @ k - a).max() < 1e-10 * np.abs(a).max()
    g = jp.T @ f
    assert np.abs(op.rmatvec(f) - g).max() < 1e-10 * np.abs(g).max()
    assert np.allclose(op.rmatvec(f), k.T @ f, rtol=0, atol=1e-10 * np.abs(g).max())


def _agree(a: ap.Calibration, b: ap.Calibration) -> None:
    assert a.names == b.names
    sd = np.sqrt(np.clip(np.diag(a.covariance), 0.0, None))
    seen = sd > 1e-12
    assert np.max(np.abs(a.x - b.x)[seen] / sd[seen]) < 1e-3
    assert np.max(np.abs(a.x - b.x)[~seen], initial=0.0) < 1e-12
    assert np.allclose(a.covariance, b.covariance, rtol=0,
                       atol=1e-6 * np.abs(a.covariance).max())
    assert abs(a.fit_rms - b.fit_rms) < 1e-9 * a.fit_rms


def _count_whole_jacobians(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Record the samples of every whole Jacobian built from now on (``Unknowns.jacobian``)."""
    built: list[int] = []
    whole_jacobian = unk.Unknowns.jacobian

    def spy(self: unk.Unknowns, x: np.ndarray, q: np.ndarray):  # type: ignore[no-untyped-def]
        built.append(q.shape[0])
        return whole_jacobian(self, x, q)

    monkeypatch.setattr(unk.Unknowns, "jacobian", spy)
    return built


def test_a_fit_in_small_chunks_equals_one_in_a_single_chunk_and_the_whole(
        arm: ap.Arm, sim: ap.Simulation, cal: ap.Calibration, monkeypatch: pytest.MonkeyPatch):
    """The chunked route, never holding the whole Jacobian, lands where the usual one does."""
    built = _count_whole_jacobians(monkeypatch)
    _chunked(monkeypatch, 10 ** 9)
    one = identify(sim.campaign, arm)
    _chunked(monkeypatch, 96)
    small = identify(sim.campaign, arm)
    assert built == []  # no Jacobian of all the samples was built
    assert one.problem.chunked and small.problem.chunked and not cal.problem.chunked
    assert one.success and small.success
    _agree(one, small)
    _agree(cal, small)


def test_the_threshold_is_the_jacobians_bytes(cal: ap.Calibration):
    n = cal.problem.q.shape[0]
    _, whole = cal.unknowns.jacobian(cal.x[:cal.problem.n_arm], cal.problem.q)
    held = whole.dense.nbytes + sum(a.col.nbytes + a.weight.nbytes + a.d.nbytes
                                    for a in whole.axes)
    assert cj.jacobian_bytes(cal.unknowns, n) == held


def _passes_and_residuals(arm: ap.Arm, sim: ap.Simulation, monkeypatch: pytest.MonkeyPatch
                          ) -> tuple[ap.Calibration, int, int]:
    """Identify; return the calibration, the Jacobians built (whole, or passes over the chunks:
    a chunk starting at sample 0) and the residual evaluations made apart from those passes."""
    count = {"jacobians": 0, "positions": 0}
    rows, whole, positions = (unk.Unknowns.jacobian_rows, unk.Unknowns.jacobian,
                              unk.Unknowns.positions)

    def rows_spy(self: unk.Unknowns, x: np.ndarray, q: np.ndarray, lo: int, hi: int,
                 work: dict[str, np.ndarray] | None = None):  # type: ignore[no-untyped-def]
        count["jacobians"] += lo == 0
        return rows(self, x, q, lo, hi, work)

    def whole_spy(self: unk.Unknowns, x: np.ndarray, q: np.ndarray):  # type: ignore[no-untyped-def]
        count["jacobians"] += 1
        return whole(self, x, q)

    def positions_spy(self: unk.Unknowns, x: np.ndarray, q: np.ndarray
                      ):  # type: ignore[no-untyped-def]
        count["positions"] += 1
        return positions(self, x, q)

    with monkeypatch.context() as m:
        m.setattr(unk.Unknowns, "jacobian_rows", rows_spy)
        m.setattr(unk.Unknowns, "jacobian", whole_spy)
        m.setattr(unk.Unknowns, "positions", positions_spy)
        cal = identify(sim.campaign, arm)
    return cal, count["jacobians"], count["positions"]


def test_a_chunked_fit_takes_no_more_passes_than_the_whole_route_builds_jacobians(
        arm: ap.Arm, sim: ap.Simulation, monkeypatch: pytest.MonkeyPatch):
    """Issue 28: the large path's CPU per sample is the whole route's. Every pass over the chunks
    rebuilds the Jacobian (most of a sample's CPU): the gauge check's pass also takes the first
    problem's products, and a residual the solver (or the decision point) evaluates takes its
    Jacobian's products in the same pass, so a chunked fit makes at most as many passes as the
    whole route builds Jacobians, and evaluates positions apart from them only at the start (before
    its first pass) and for the report."""
    whole, built, evaluated = _passes_and_residuals(arm, sim, monkeypatch)
    _chunked(monkeypatch, 96)
    chunked, passes, alone = _passes_and_residuals(arm, sim, monkeypatch)
    assert chunked.problem.chunked and not whole.problem.chunked
    assert chunked.nfev == whole.nfev  # the same evaluations, counted the same way
    assert passes <= built
    assert alone == 2 < evaluated
    _agree(whole, chunked)


def test_a_residual_evaluated_in_a_pass_is_funs_and_keeps_its_products(
        cal: ap.Calibration, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(cj, "CHUNKED_BYTES", 0)
    monkeypatch.setattr(cj, "CHUNK_SAMPLES", 128)
    prob = cal.problem
    prob = type(prob).__new__(type(prob))
    prob.__dict__.update(cal.problem.__dict__, chunked=True)
    z = prob.z(cal.x) + 0.1
    f, jac = prob.fun_with_products(z)
    assert np.array_equal(f, prob.fun(z))  # the same numbers, bit for bit
    x = prob.x(z)
    nuis = prob.nuisance_jacobian(x)
    fresh = ChunkedJacobian(cal.unknowns, x[:prob.n_arm], prob.q).products(nuis, f[:prob.n_data])
    monkeypatch.setattr(jac, "chunks", lambda products=False: iter(()))  # kept: no pass
    for kept, ref in zip(jac.products(nuis, f[:prob.n_data]), fresh):
        assert kept is not None and ref is not None
        assert np.array_equal(kept, ref)


@pytest.mark.parametrize("first", ["gauge check", "normal"])
def test_products_deferred_to_the_gauge_check_take_no_pass_of_their_own(
        cal: ap.Calibration, monkeypatch: pytest.MonkeyPatch, first: str):
    monkeypatch.setattr(cj, "CHUNK_SAMPLES", 128)
    prob = cal.problem
    x = cal.x
    chunked = ChunkedJacobian(cal.unknowns, x[:prob.n_arm], prob.q)
    nuis = prob.nuisance_jacobian(x)
    f = prob.fun(prob.z(x))[:prob.n_data]
    chunked.defer(nuis, f)
    if first == "gauge check":
        ident.gauge_axes(cal.unknowns, chunked)
    else:  # J^T J asked alone (no map axes: no gauge pass): the deferred products ride on it
        chunked.normal()
    monkeypatch.setattr(chunked, "chunks", lambda products=False: iter(()))
    normal, cross, grad = chunked.products(nuis, f)
    _, whole = cal.unknowns.jacobian(x[:prob.n_arm], prob.q)
    assert np.abs(normal - whole.normal()).max() < 1e-12 * np.abs(normal).max()
    assert cross is not None and grad is not None
    assert np.allclose(cross, whole.cross(nuis), rtol=0, atol=1e-12 * np.abs(cross).max())
    assert np.allclose(grad, whole.rmatmul(f), rtol=0, atol=1e-12 * np.abs(grad).max())


def test_node_sensitivities_chunk_by_chunk_are_the_whole_blocks_bit_for_bit(
        cal: ap.Calibration, monkeypatch: pytest.MonkeyPatch):
    """``--robust``'s unseen-node check of a large campaign builds no whole Jacobian: the
    per-sample node sensitivities summed chunk by chunk are the whole node block's numbers."""
    monkeypatch.setattr(cj, "CHUNK_SAMPLES", 128)
    x, q = cal.x[:cal.problem.n_arm], cal.problem.q
    whole = rob.node_sensitivity(cal.unknowns.jacobian(x, q)[1].nodes, len(q))
    chunked = cj.chunked_node_sensitivity(ChunkedJacobian(cal.unknowns, x, q))
    assert chunked.shape == whole.shape
    for a, b in ((chunked.row, whole.row), (chunked.col, whole.col), (chunked.data, whole.data)):
        assert np.array_equal(a, b)


@pytest.mark.slow  # two robust fits (8 s of CPU)
def test_a_robust_fit_in_chunks_builds_no_whole_jacobian_and_equals_the_whole_route(
        arm: ap.Arm, sim_400: ap.Simulation, monkeypatch: pytest.MonkeyPatch):
    sim = sim_400
    displacement = sim.campaign.spat.displacement.copy()
    displacement[[7, 205]] += 60e-6  # two gross outliers (30 sigma)
    camp = sim.campaign.with_spat(displacement=displacement)
    whole = identify(camp, arm, robust=True)
    built = _count_whole_jacobians(monkeypatch)
    _chunked(monkeypatch, 96)
    chunked = identify(camp, arm, robust=True)
    assert chunked.problem.chunked and built == []
    assert chunked.inlier is not None and whole.inlier is not None
    assert np.array_equal(chunked.inlier, whole.inlier) and not chunked.inlier[[7, 205]].any()
    _agree(whole, chunked)
