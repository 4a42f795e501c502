"""Kinematics against the paper's equations, and every Jacobian against finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from aacmm_pin.effects import calibrated as kinematics
from aacmm_pin.model.encoder_map import EncoderMap
from aacmm_pin.model.parameters import Parameters
from tests.helpers import paper_stylus, paper_to_mt, random_dh


def random_parameters(arm, seed: int) -> Parameters:
    rng = np.random.default_rng(seed)
    maps = {axis: EncoderMap(rng.normal(0, 1e-4, 72)) for axis in range(1, 8)}
    return Parameters(arm="aacmm7", dh=random_dh(rng), tool=rng.normal([0, 0, -0.12], 0.01),
                      rotation_abc=rng.normal(0, 0.02, 3), translation=rng.normal(0, 0.5, 3),
                      encoder_maps=maps)


def away_from_nodes(rng: np.random.Generator, n: int, margin_deg: float = 0.5) -> np.ndarray:
    """Readouts (rad) in any turn, at least margin_deg from a map node (the maps have kinks there)."""
    deg = rng.uniform(-700, 700, (n, 7))
    frac = np.mod(deg, 5.0)
    deg = np.where(frac < margin_deg, deg + margin_deg, deg)
    deg = np.where(np.mod(deg, 5.0) > 5.0 - margin_deg, deg - margin_deg, deg)
    return np.radians(deg)


def test_zero_readouts_put_stylus_at_nominal_point(arm):
    """At zero readouts the nominal stylus centre is (750, 0, -420) mm."""
    p = kinematics.stylus_positions(arm, Parameters.nominal(arm), np.zeros((1, 7)))
    np.testing.assert_allclose(p[0] * 1e3, [750.0, 0.0, -420.0], atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_positions_match_paper_transcription(arm, seed):
    """Stylus positions equal the independent transcription of Eq. (1)-(4) to 1e-9 mm."""
    params = random_parameters(arm, seed)
    rng = np.random.default_rng(100 + seed)
    q = rng.uniform(-4 * np.pi, 4 * np.pi, (50, 7))
    maps = {a: m.values for a, m in params.encoder_maps.items()}
    ref_r = np.array([paper_stylus(qi, params.dh, params.tool, maps) for qi in q])
    ref_mt = np.array([paper_to_mt(p, params.rotation_abc, params.translation) for p in ref_r])
    np.testing.assert_allclose(kinematics.stylus_positions(arm, params, q, "r") * 1e3,
                               ref_r * 1e3, rtol=0, atol=1e-9)
    np.testing.assert_allclose(kinematics.stylus_positions(arm, params, q, "mt") * 1e3,
                               ref_mt * 1e3, rtol=0, atol=1e-9)
    np.testing.assert_allclose(kinematics.predict(arm, params, q) * 1e3, ref_r * 1e3,
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(kinematics.stylus_jacobians(arm, params, q, "mt").position * 1e3,
                               ref_mt * 1e3, rtol=0, atol=1e-9)


# Central differences with h = 1e-6 (rad or m): truncation ~ h^2 |p'''| / 6 < 1e-12 m and
# round-off ~ eps |p| / h ~ 3e-10 m, so 1e-8 (m per unit) bounds an exact Jacobian; a wrong column
# is off by O(1) of its size (> 1e-3 m per rad here).
H, ATOL = 1e-6, 1e-8


def _central(f, x0: np.ndarray, k: int) -> np.ndarray:
    xp, xm = x0.copy(), x0.copy()
    xp[k] += H
    xm[k] -= H
    return (f(xp) - f(xm)) / (2 * H)


@pytest.fixture(scope="module")
def case(arm):
    params = random_parameters(arm, 7)
    q = away_from_nodes(np.random.default_rng(8), 20)
    return params, q, kinematics.stylus_jacobians(arm, params, q, frame="mt")


def test_jacobian_readouts(arm, case):
    """d(stylus)/d(readouts), map slopes included, matches central differences."""
    params, q, jac = case
    for n in range(7):
        qp, qm = q.copy(), q.copy()
        qp[:, n] += H
        qm[:, n] -= H
        fd = (kinematics.stylus_positions(arm, params, qp, "mt")
              - kinematics.stylus_positions(arm, params, qm, "mt")) / (2 * H)
        np.testing.assert_allclose(jac.readouts[:, :, n], fd, atol=ATOL, rtol=0)


def test_jacobian_dh_parameters(arm, case):
    """d(stylus)/d(each of the 22 DH parameters) matches central differences."""
    params, q, jac = case
    names = arm.error_names
    x0 = np.array([params.dh[n] for n in names])
    for k, name in enumerate(names):
        fd = _central(lambda x: kinematics.stylus_positions(
            arm, params.replace(dh=dict(zip(names, x))), q, "mt"), x0, k)
        np.testing.assert_allclose(jac.dh[:, :, k], fd, atol=ATOL, rtol=0, err_msg=name)


@pytest.mark.parametrize("field, block", [("tool", "tool"), ("rotation_abc", "rotation"),
                                          ("translation", "translation")])
def test_jacobian_tool_and_x0(arm, case, field, block):
    """d(stylus)/d(tool vector, X0 angles, translation) matches central differences."""
    params, q, jac = case
    x0 = getattr(params, field).copy()
    for k in range(3):
        fd = _central(lambda x: kinematics.stylus_positions(
            arm, params.replace(**{field: x}), q, "mt"), x0, k)
        np.testing.assert_allclose(getattr(jac, block)[:, :, k], fd, atol=ATOL, rtol=0)


@pytest.mark.parametrize("axis", range(1, 8))
def test_jacobian_map_nodes(arm, case, axis):
    """d(stylus)/d(every node of every map) matches central differences (sparse, sample-major)."""
    params, q, jac = case
    dense = jac.nodes(params, axis).toarray()  # (3N, 72)
    values = params.map(axis).values.copy()
    visited = np.unique(np.nonzero(dense)[1])
    assert visited.size > 0
    for k in range(72):
        def f(x):
            maps = dict(params.encoder_maps)
            maps[axis] = EncoderMap(x)
            return kinematics.stylus_positions(arm, params.replace(encoder_maps=maps), q, "mt")
        np.testing.assert_allclose(dense[:, k], _central(f, values, k).reshape(-1),
                                   atol=ATOL, rtol=0, err_msg=f"node {k}")
