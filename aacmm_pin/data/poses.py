"""Poses as units: which samples share one pose of the arm, and held-out folds that keep them together.

An instrument may see several points of one pose (two markers, two tools of a tree): those rows
share their readouts, and a held-out split that puts one on each side predicts the left-out row
from a fit that saw its pose. A pose is named by the ``pose`` column of ``points.csv`` (any numbers:
rows with the same value are one pose) or, without it, by identical readouts in consecutive rows
(what an export of several markers per pose writes). :func:`pose_ids` numbers the poses;
:func:`pose_folds` splits them into k folds, poses whole.
"""

from __future__ import annotations

import numpy as np

POSE_COLUMN = "pose"
"""Name of the per-sample column of ``points.csv`` that names each row's pose."""


def pose_ids(q: np.ndarray, pose: np.ndarray | None = None) -> np.ndarray:
    """Return the pose of every sample, numbered 0, 1, ... in order of first appearance.

    Args:
        q: readouts, shape (N, n_axes), rad.
        pose: the ``pose`` column, shape (N,) (equal values: one pose), or None: consecutive rows
            with identical readouts are one pose.

    Returns:
        Pose index of each sample, shape (N,), int64.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = len(q)
    if pose is not None:
        values = np.asarray(pose)
        if values.shape != (n,):
            raise ValueError(f"pose: shape ({n},) expected, got {values.shape}")
        _, first, inverse = np.unique(values, return_index=True, return_inverse=True)
        rank = np.empty(len(first), dtype=np.int64)
        rank[np.argsort(first, kind="stable")] = np.arange(len(first))
        out: np.ndarray = rank[inverse.ravel()]
        return out
    new = np.ones(n, dtype=bool)
    if n > 1:
        new[1:] = np.any(q[1:] != q[:-1], axis=1)
    return np.cumsum(new) - 1


def pose_folds(ids: np.ndarray, folds: int, seed: int = 0) -> list[np.ndarray]:
    """Return the rows of each of ``folds`` held-out folds, every pose whole in one fold.

    The poses are shuffled (``numpy.random.default_rng(seed)``) and split into ``folds`` parts of
    nearly equal numbers of poses (``numpy.array_split``). With one sample per pose this is the
    split of the samples themselves: the same rows, in the same order.

    Args:
        ids: pose of every sample, shape (N,) (:func:`pose_ids`).
        folds: number of folds (>= 1).
        seed: seed of the shuffle.

    Returns:
        Sample rows of each fold (indices, ascending within each pose's order of the shuffle).
    """
    ids = np.asarray(ids, dtype=np.int64)
    n_poses = int(ids.max()) + 1 if ids.size else 0
    by_pose = np.argsort(ids, kind="stable")  # rows of pose p: by_pose[bounds[p]:bounds[p + 1]]
    bounds = np.searchsorted(ids[by_pose], np.arange(n_poses + 1))
    order = np.random.default_rng(seed).permutation(n_poses)
    return [np.concatenate([by_pose[bounds[p]:bounds[p + 1]] for p in part]).astype(np.int64)
            if len(part) else np.zeros(0, dtype=np.int64) for part in np.array_split(order, folds)]
