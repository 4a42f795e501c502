"""A large campaign's peak memory (issue 41): what is computed per sample is computed block by block.

The start's frame (:func:`aacmm_pin.model.kinematics.stylus_positions` over every sample), the
URDF-alone loss the calibration folder reports (:func:`aacmm_pin.analyses.urdf_loss.urdf_alone_loss`)
and the chunked Jacobian's passes held the configurations of every sample at once (8 ``nq`` bytes
a sample: 0.5 GB at 1.6M samples of the paper's arm, the CLI's peak), or one set of chunk buffers
per Jacobian alive. Each test pins the same numbers as before, bit for bit, and the memory
property at a size the default run affords (``tracemalloc``: numpy's arrays are traced; the
bounds are stated from the arrays' sizes, not fitted to a measurement).
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses import urdf_loss
from aacmm_pin.fit import chunked_jacobian as cj
from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian
from aacmm_pin.model import kinematics
from aacmm_pin.model.compact_urdf import compact_urdf
from aacmm_pin.model.samples import Samples

N = 20_000
"""Samples of the memory tests (a few hundred kB per array of N positions)."""
BLOCK = 1024
"""Block size the memory tests set: the blocks' own arrays stay far below the N-sized ones."""


def _peak(call: Callable[[], Any]) -> tuple[Any, int]:
    """Return call()'s result and the peak of the memory traced during it, bytes."""
    tracemalloc.start()
    try:
        out = call()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return out, peak


def _readouts(arm: ap.Arm, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-np.pi, np.pi, (n, arm.n_axes))


def test_positions_in_blocks_are_those_of_one_call(arm: ap.Arm, small_cal: ap.Calibration,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    q = _readouts(arm, 3 * 4096 + 77)
    params = small_cal.parameters
    whole = {frame: kinematics.stylus_positions(arm, params, q, frame) for frame in ("r", "mt")}
    monkeypatch.setattr(kinematics, "POSITIONS_CHUNK", 4096)  # the chain's own block
    for frame, ref in whole.items():
        assert np.array_equal(kinematics.stylus_positions(arm, params, q, frame), ref)
    monkeypatch.setattr(kinematics, "POSITIONS_CHUNK", 1000)  # not a multiple: still per sample
    assert np.array_equal(kinematics.stylus_positions(arm, params, q, "r"), whole["r"])


def test_positions_hold_one_blocks_configurations(arm: ap.Arm,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole call's peak holds every sample's configuration (8 nq bytes a sample); in blocks
    the peak is the result (24 bytes a sample), the tool frames (8) and the readouts' own checks,
    under 8 nq bytes a sample (nq = 38 on this arm: 304)."""
    q = _readouts(arm, N)
    params = ap.Parameters.nominal(arm)
    nq = arm.identification.model.nq
    assert nq * 8 >= 200
    monkeypatch.setattr(kinematics, "POSITIONS_CHUNK", 10 * N)
    whole, peak_whole = _peak(lambda: kinematics.stylus_positions(arm, params, q))
    monkeypatch.setattr(kinematics, "POSITIONS_CHUNK", BLOCK)
    blocks, peak_blocks = _peak(lambda: kinematics.stylus_positions(arm, params, q))
    assert np.array_equal(blocks, whole)
    assert peak_whole > 8 * nq * N  # the configurations, all at once
    block_bytes = 40 * BLOCK * (nq + 3 * arm.n_axes)  # a block's configurations and corrections
    assert peak_blocks < (24 + 8 + 16) * N + block_bytes, (peak_blocks, peak_whole)


@pytest.fixture(scope="module")
def loss_inputs(arm: ap.Arm, small_cal: ap.Calibration) -> tuple[Any, ...]:
    params = small_cal.parameters
    tree = arm.urdf_tree(params.dh, tools=params.tool_vectors(arm))
    return arm, params, compact_urdf(tree)


def test_the_urdf_loss_in_blocks_is_the_whole_ones(loss_inputs: tuple[Any, ...],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    arm, params, urdf = loss_inputs
    poses = [Samples(arm, _readouts(arm, 5000, seed)) for seed in (1, 2)]  # two files
    monkeypatch.setattr(urdf_loss, "LOSS_BLOCK", 10 ** 6)
    whole = urdf_loss.urdf_alone_loss(arm, params, urdf, poses)
    monkeypatch.setattr(urdf_loss, "LOSS_BLOCK", 4096)
    assert urdf_loss.urdf_alone_loss(arm, params, urdf, poses) == whole  # exactly
    monkeypatch.setattr(urdf_loss, "LOSS_BLOCK", 999)
    assert urdf_loss.urdf_alone_loss(arm, params, urdf, poses) == whole
    assert whole.n_poses == 10_000 and whole.rms > 0


def test_the_urdf_loss_holds_one_blocks_kinematics(loss_inputs: tuple[Any, ...],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """In blocks: the distances (8 bytes a pose, kept for the RMS) and one block's arrays; the
    whole part at once held its readouts corrected, its joint angles and configurations (each
    8 n_axes bytes a pose) and both models' positions (24 each)."""
    arm, params, urdf = loss_inputs
    poses = [Samples(arm, _readouts(arm, N))]
    monkeypatch.setattr(urdf_loss, "LOSS_BLOCK", 10 * N)
    whole, peak_whole = _peak(lambda: urdf_loss.urdf_alone_loss(arm, params, urdf, poses))
    monkeypatch.setattr(urdf_loss, "LOSS_BLOCK", BLOCK)
    blocks, peak_blocks = _peak(lambda: urdf_loss.urdf_alone_loss(arm, params, urdf, poses))
    assert blocks == whole
    assert peak_whole > (3 * 8 * arm.n_axes + 2 * 24) * N
    assert peak_blocks < 2 * 8 * N + 60 * BLOCK * 8 * arm.n_axes, (peak_blocks, peak_whole)


def test_a_pass_reuses_its_chunk_buffers_and_frees_them(cal_400: ap.Calibration,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Every chunk of a pass is written into the same buffers (the last, shorter one into their
    front); a Jacobian holds none between passes (the solver holds one while it works on the row
    space: 80 MB at 1.6M samples); a pass within a pass has its own (the same numbers)."""
    monkeypatch.setattr(cj, "CHUNK_SAMPLES", 128)  # 400 samples: chunks of 128, 128, 128, 16
    prob, x = cal_400.problem, cal_400.x
    jac = ChunkedJacobian(cal_400.unknowns, x[:prob.n_arm], prob.q)
    first: np.ndarray | None = None
    sizes = []
    for a, b, part in jac.chunks():
        first = part.dense if first is None else first
        assert np.shares_memory(part.dense, first)
        sizes.append((b - a) // 3)
    assert sizes == [128, 128, 128, 16]
    normal = jac.normal()
    n = len(prob.q)
    held = [k for k, v in vars(jac).items() if isinstance(v, np.ndarray) and k != "q"
            and n in v.shape or 3 * n in getattr(v, "shape", ())]
    assert not held  # J^T J and the like only: no rows of samples (q is the campaign's)
    outer = ChunkedJacobian(cal_400.unknowns, x[:prob.n_arm], prob.q)
    inner = []
    for i, (_, _, part) in enumerate(outer.chunks(products=True)):
        if i == 1:
            kept = part.dense.copy()
            inner.append(ChunkedJacobian(cal_400.unknowns, x[:prob.n_arm], prob.q).normal())
            assert np.array_equal(part.dense, kept)  # the outer pass's rows untouched
    assert np.array_equal(inner[0], normal) and np.array_equal(outer.normal(), normal)


@pytest.mark.parametrize("nest", [[0, 1, -1, 2, 0, -1], [-1, -1], [0, 0, 0], []])
def test_nest_rows_are_the_matrix_built_from_coordinates(nest: list[int]) -> None:
    """The nests' rows built in CSR directly: the matrix scipy's conversion from coordinates
    gives (values, indices, their 32-bit type, canonical order), without its 64-bit arrays."""
    import scipy.sparse as sp

    from aacmm_pin.fit.data_rows import nest_rows

    arr = np.array(nest, dtype=np.int64)
    has = np.flatnonzero(arr >= 0)
    rows = (3 * has[:, None] + np.arange(3)).ravel()
    cols = (3 * arr[has][:, None] + np.arange(3)).ravel()
    ref = sp.csr_matrix((-np.ones(rows.size), (rows, cols)), shape=(3 * arr.size, 9))
    got = nest_rows(arr, 9)
    assert got.shape == ref.shape and got.has_canonical_format
    for name in ("data", "indices", "indptr"):
        assert np.array_equal(getattr(got, name), getattr(ref, name))
        assert getattr(got, name).dtype == getattr(ref, name).dtype
