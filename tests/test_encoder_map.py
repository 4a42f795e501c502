"""Encoder error maps: node table, periodic linear interpolation, weights and slopes."""

from __future__ import annotations

import numpy as np
import pytest

from aacmm_pin.model.encoder_map import (
    EncoderMap,
    correct_readouts,
    correct_with_slopes,
    node_angles,
    node_count,
)
from tests.helpers import map_error


@pytest.fixture
def emap():
    return EncoderMap(np.random.default_rng(3).normal(0, 1e-4, 72))


def test_nodes_from_minus_180_by_step():
    """Nodes sit at -180, -175, ..., 175 deg by default; a 10 deg step gives 36."""
    np.testing.assert_allclose(np.degrees(node_angles()), np.arange(-180, 180, 5.0))
    assert node_count(10.0) == 36
    with pytest.raises(ValueError, match="divide 360"):
        node_count(7.0)


def test_value_at_nodes_is_table_value(emap):
    """Interpolating exactly at a node returns that node's value, in any turn."""
    for turn in (-2, 0, 1, 3):
        np.testing.assert_allclose(emap(emap.nodes + 2 * np.pi * turn), emap.values, atol=1e-15)


def test_matches_independent_interpolation(emap):
    """The map equals the test's own transcription of periodic linear interpolation."""
    readouts = np.random.default_rng(4).uniform(-13, 13, 500)
    ref = [map_error(emap.values, r) for r in readouts]
    np.testing.assert_allclose(emap(readouts), ref, atol=1e-15)


def test_weights_reproduce_values_and_are_linear_in_nodes(emap):
    """W @ values equals the map, rows sum to one, at most two nonzeros per row."""
    readouts = np.random.default_rng(5).uniform(-np.pi, np.pi, 300)
    w = emap.weights(readouts)
    np.testing.assert_allclose(w @ emap.values, emap(readouts), atol=1e-15)
    np.testing.assert_allclose(np.asarray(w.sum(axis=1)).ravel(), 1.0)
    assert max(np.diff(w.indptr)) <= 2


def test_slope_matches_finite_difference_inside_segments(emap):
    """slope() is the derivative of the map between nodes."""
    readouts = np.radians(np.arange(-177.5, 180, 5.0))  # mid-segments, away from the kinks
    h = 1e-7
    fd = (emap(readouts + h) - emap(readouts - h)) / (2 * h)
    np.testing.assert_allclose(emap.slope(readouts), fd, rtol=1e-6, atol=1e-12)


def test_wraps_configurations(emap):
    """correct_readouts adds each axis' error; axes without a map are unchanged."""
    q = np.random.default_rng(6).uniform(-3, 3, (10, 7))
    out = correct_readouts(q, {2: emap})
    np.testing.assert_allclose(out[:, 1], q[:, 1] + emap(q[:, 1]))
    np.testing.assert_array_equal(np.delete(out, 1, axis=1), np.delete(q, 1, axis=1))


def test_rejects_wrong_node_count_and_nan():
    """A table of the wrong length or with NaN is refused with the argument named."""
    with pytest.raises(ValueError, match="72 nodes"):
        EncoderMap(np.zeros(71))
    with pytest.raises(ValueError, match="finite"):
        EncoderMap(np.full(72, np.nan))


def test_node_columns_are_angle_columns_times_weights(emap):
    """Node columns equal d(point)/d(angle) x interpolation weight, with held nodes left out."""
    rng = np.random.default_rng(11)
    readout = np.concatenate([rng.uniform(-7.0, 7.0, 300), emap.nodes[:5]])  # some on nodes
    d_angle = rng.normal(size=(readout.size, 3))
    keep = rng.random(emap.n_nodes) > 0.3
    weights = emap.weights(readout).toarray()                     # (N, n_nodes)
    expected = (d_angle[:, :, None] * weights[:, None, :]).reshape(3 * readout.size, -1)[:, keep]
    cols = emap.node_columns(readout, d_angle, keep)
    assert cols.format == "csc" and cols.has_canonical_format
    np.testing.assert_array_equal(cols.toarray(), expected)
    assert cols.nnz == np.count_nonzero(np.repeat(weights[:, keep], 3, axis=0))
    np.testing.assert_array_equal(emap.node_columns(readout, d_angle).toarray(),
                                  (d_angle[:, :, None] * weights[:, None, :]).reshape(
                                      3 * readout.size, -1))


@pytest.mark.parametrize("steps", [(5.0, 5.0), (5.0, 2.5)])
def test_correct_with_slopes_equals_the_per_axis_functions(steps):
    """All axes in one pass (one node step) or axis by axis (several): the same angles and
    slopes as correct_readouts and 1 + EncoderMap.slope, axes without a map unchanged."""
    rng = np.random.default_rng(11)
    maps = {a: EncoderMap(rng.normal(0.0, 1e-4, node_count(s)), s) for a, s in zip((2, 5), steps)}
    q = rng.uniform(-7.0, 7.0, (30, 6))
    angles, slopes = correct_with_slopes(q, maps)
    np.testing.assert_array_equal(angles, correct_readouts(q, maps))
    expected = np.ones_like(q)
    for a, m in maps.items():
        expected[:, a - 1] += m.slope(q[:, a - 1])
    np.testing.assert_array_equal(slopes, expected)
    assert np.all(slopes[:, [0, 2, 3, 5]] == 1.0) and np.all(slopes[:, [1, 4]] != 1.0)


def test_correct_readouts_and_its_inverse_refuse_bad_arrays_in_one_line() -> None:
    """A q without a column for a mapped axis (was a bare IndexError) or with NaN is refused in one
    line naming the argument; readouts_of_angles alike."""
    import aacmm_pin as ap

    maps = {a: ap.EncoderMap.zero() for a in range(1, 8)}
    for f, name in ((ap.correct_readouts, "q"), (ap.readouts_of_angles, "angles")):
        with pytest.raises(ap.ArgumentError, match=rf"^{name}: need shape .* got shape \(3, 6\)$"):
            f(np.zeros((3, 6)), maps)
        with pytest.raises(ap.ArgumentError, match=rf"^{name}: every value must be a finite"):
            f(np.array([0.0, 1.0, np.nan, 0, 0, 0, 0]), maps)
        assert f(np.zeros((3, 7)), maps).shape == (3, 7)
