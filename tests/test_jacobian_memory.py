"""A campaign's Jacobian costs what it holds (issue 28): no second copy of it while the next one
is built, and no dense copy of the sparse nest and frame columns when they meet the map nodes.

Sizes: the block Jacobian of N samples holds 8 bytes per entry of its (3N, n) dense block; a dense
copy of the nests' columns holds 3N k x 8 bytes. The tests compare the memory a call allocates
(``tracemalloc``, which counts numpy's buffers exactly) with those sizes.
"""

from __future__ import annotations

import gc
import tracemalloc
import weakref

import numpy as np
import scipy.sparse as sp

import aacmm_pin as ap
from aacmm_pin.fit.unknowns import CHUNK, AxisNodes, BlockJacobian, Unknowns


def test_the_previous_jacobian_is_released_before_the_next_is_built(arm: ap.Arm):
    """Unknowns.jacobian keeps the last Jacobian (a cache); at another point it builds a new one.
    The cached one must be gone before the new one is built, else two Jacobians (hundreds of MB
    each on a large campaign) share the peak."""
    rng = np.random.default_rng(0)
    q = rng.uniform(-2.0, 2.0, (500, arm.n_axes))
    u = Unknowns.full(arm, ap.Parameters.nominal(arm), tuple(range(1, arm.n_axes + 1)))
    x = u.vector(u.start)
    old = weakref.ref(u.jacobian(x, q)[1])  # only the cache holds it now
    assert old() is not None
    seen = []
    build = u._chain_blocks

    def spy(params, q_):
        gc.collect()
        seen.append(old() is None)
        return build(params, q_)

    object.__setattr__(u, "_chain_blocks", spy)
    u.jacobian(x + 1e-6, q)
    assert seen == [True]


def _block(n: int, n_dense: int, sizes: tuple[int, ...], seed: int = 0) -> BlockJacobian:
    """A block Jacobian of n samples with random entries and map axes of the given node counts."""
    rng = np.random.default_rng(seed)
    axes, at = [], 0
    for size in sizes:
        lower = rng.integers(0, size - 1, n)
        col = np.column_stack([lower, lower + 1])
        frac = rng.random(n)
        axes.append(AxisNodes(col, np.column_stack([1.0 - frac, frac]), rng.normal(size=(n, 3)),
                              at, size))
        at += size
    return BlockJacobian(rng.normal(size=(3 * n, n_dense)), tuple(axes), at)


def _nests(n: int, n_nests: int, seed: int = 1) -> sp.csr_matrix:
    """d(residual)/d(nest offsets): -1 on each sample's nest and coordinate, shape (3N, 3 n_nests)."""
    nest = np.random.default_rng(seed).integers(0, n_nests, n)
    rows = np.arange(3 * n)
    cols = (3 * nest[:, None] + np.arange(3)).ravel()
    return sp.csr_matrix((-np.ones(3 * n), (rows, cols)), shape=(3 * n, 3 * n_nests))


def test_node_products_with_sparse_columns_match_and_need_no_dense_copy():
    """The map nodes' product with the nests' sparse columns (the normal matrix's cross terms)
    equals the product with their dense copy, to the last bit, and allocates less than that copy
    would (it is made dense one block of rows at a time)."""
    n, k = 6 * CHUNK, 12
    jac, nests = _block(n, 4, (30, 30, 30)), _nests(n, k // 3)
    dense_copy = 3 * n * k * 8  # bytes
    expected = jac.node_rmatmul(nests.toarray())
    gc.collect()
    tracemalloc.start()
    got = jac.node_rmatmul(nests)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert np.array_equal(got, expected)
    assert peak < dense_copy, (peak, dense_copy)


def test_the_jacobian_holds_its_entries_and_no_more(arm: ap.Arm):
    """The dense block the solver keeps is one contiguous array of exactly its entries: the map
    axes' angle columns, read once to build the node columns, are not kept beside it (7 columns,
    168 bytes per sample), and products with it need no contiguous copy (a copy of the whole block
    at each normal matrix)."""
    rng = np.random.default_rng(0)
    q = rng.uniform(-2.0, 2.0, (300, arm.n_axes))
    u = Unknowns.full(arm, ap.Parameters.nominal(arm), tuple(range(1, arm.n_axes + 1)))
    jac = u.jacobian(u.vector(u.start), q)[1]
    dense = jac.dense
    assert dense.flags.c_contiguous
    owner = dense if dense.base is None else dense.base
    while isinstance(owner.base, np.ndarray):
        owner = owner.base
    assert owner.nbytes == dense.nbytes


def test_the_kept_jacobian_goes_with_its_calibration(arm: ap.Arm, small_sim: ap.Simulation):
    """A calibration released leaves no Jacobian behind (the process' slot holds it weakly)."""
    from aacmm_pin.fit.jacobian_cache import LAST_JACOBIAN

    cal = ap.identify(small_sim.campaign, arm)
    assert LAST_JACOBIAN._held is not None  # kept for the analyses after the fit
    layout = weakref.ref(cal.unknowns)
    del cal
    gc.collect()
    assert layout() is None
    assert LAST_JACOBIAN._held is None
