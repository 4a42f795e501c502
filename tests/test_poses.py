"""Poses as units: the points of one pose (two markers) stay together in every held-out split."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.linear_scorer import FOLDS, LinearScorer
from aacmm_pin.data.campaign import PointLog, read_campaign, write_campaign
from aacmm_pin.data.point_import import PointFormat, import_points
from aacmm_pin.data.poses import pose_folds, pose_ids
from aacmm_pin.fit.measurements import measurements

ROOT = Path(__file__).resolve().parents[1]
SIGMA = 20e-6  # tracker noise per coordinate, m
N_POSES = 40


@pytest.fixture(scope="module")
def torso() -> ap.Arm:
    return ap.load_arm(ROOT / "urdf" / "torso.urdf")


def _two_markers(arm: ap.Arm, order: str, seed: int = 0) -> ap.Campaign:
    """Both markers of N_POSES random poses: ``"pairs"`` (left, right of a pose in consecutive
    rows, no pose column) or ``"blocks"`` (every left marker, then every right one; a pose column)."""
    rng = np.random.default_rng(seed)
    lim = arm.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (N_POSES, arm.n_axes))
    truth = ap.Parameters.nominal(arm, 5.0)
    pose = np.arange(N_POSES)
    if order == "pairs":
        pose, tool = np.repeat(pose, 2), np.tile(["left", "right"], N_POSES)
    else:
        pose, tool = np.tile(pose, 2), np.repeat(["left", "right"], N_POSES)
    point = (ap.stylus_positions(arm, truth, q[pose], frame="mt", tool=tool)
             + rng.normal(0.0, SIGMA, (len(pose), 3)))
    columns = {"pose": 100.0 + pose} if order == "blocks" else {}
    return ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.ones(len(pose), dtype=np.int64), q=q[pose], point=point, tool=tool,
        columns=columns))


def _split_poses(groups: list[np.ndarray], pose: np.ndarray) -> list[int]:
    """Return the poses whose samples fall in more than one held-out group."""
    fold = np.full(len(pose), -1)
    for k, rows in enumerate(groups):
        fold[np.unique(np.asarray(rows) // 3)] = k  # residual rows -> samples
    assert np.all(fold >= 0)
    return [int(p) for p in np.unique(pose) if len(set(fold[pose == p])) > 1]


@pytest.mark.parametrize("order", ["pairs", "blocks"])
def test_discover_folds_keep_both_markers_of_a_pose(tmp_path, torso, order):
    """discover's k-fold (LinearScorer's held-out groups) never separates a pose's two markers:
    by identical consecutive readouts, or by the pose column of points.csv (read back from the file)."""
    write_campaign(_two_markers(torso, order), tmp_path)
    campaign = read_campaign(tmp_path, arm=torso)
    assert campaign.points is not None
    truth_pose = (np.arange(2 * N_POSES) // 2 if order == "pairs"
                  else np.tile(np.arange(N_POSES), 2))
    cal = ap.identify(campaign, torso, model="dh")
    lin = LinearScorer(cal, measurements(campaign, torso, True).samples)
    assert len(lin.groups) == FOLDS and not any(lin.centred)
    assert _split_poses(lin.groups, truth_pose) == []
    sizes = [len(g) // 3 for g in lin.groups]  # whole poses, about equal folds
    assert sum(sizes) == 2 * N_POSES and max(sizes) - min(sizes) <= 2


def test_pose_ids_and_folds():
    """pose_ids: the pose column's values, else runs of identical readouts; pose_folds keeps each
    pose whole and, with one sample per pose, is the plain split of the samples."""
    q = np.array([[1.0, 2.0], [1.0, 2.0], [3.0, 4.0], [1.0, 2.0], [1.0, 2.0]])
    np.testing.assert_array_equal(pose_ids(q), [0, 0, 1, 2, 2])
    np.testing.assert_array_equal(pose_ids(q, np.array([7, 7, 3, 7, 3])), [0, 0, 1, 0, 1])
    ids = np.repeat(np.arange(30), 3)
    folds = pose_folds(ids, FOLDS)
    assert sorted(np.concatenate(folds).tolist()) == list(range(90))
    assert all(len(set(ids[f]) & set(ids[g])) == 0 for i, f in enumerate(folds)
               for g in folds[i + 1:])
    order = np.random.default_rng(0).permutation(23)
    for mine, plain in zip(pose_folds(np.arange(23), FOLDS), np.array_split(order, FOLDS)):
        np.testing.assert_array_equal(mine, plain)


def test_import_points_writes_the_pose_column_for_several_markers(tmp_path):
    """import-points: a source with two markers per pose (identical readouts in consecutive rows)
    gets a pose column in points.csv, numbered on across files; one point per pose gets none."""
    rng = np.random.default_rng(1)
    q = np.degrees(rng.uniform(-3.0, 3.0, (12, 6)))
    header = ["a1", "a2", "a3", "a4", "a5", "a6", "x", "y", "z"]

    def source(name: str, markers: int) -> Path:
        rows = [",".join(f"{v:.6f}" for v in [*qi, *rng.uniform(-500, 500, 3)])
                for qi in q for _ in range(markers)]
        path = tmp_path / name
        path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")
        return path

    fmt = PointFormat(tuple(header[:6]), (("x", None), ("y", None), ("z", None)))
    import_points([source("two.csv", 2), source("two_b.csv", 2)], tmp_path / "two", fmt)
    points = read_campaign(tmp_path / "two").points
    assert points is not None
    np.testing.assert_array_equal(points.columns["pose"], np.repeat(np.arange(1, 25), 2))
    import_points([source("one.csv", 1)], tmp_path / "one", fmt)
    points = read_campaign(tmp_path / "one").points
    assert points is not None and "pose" not in points.columns


def test_spat_and_points_fitted_together_keep_the_pose_column(tmp_path):
    """SPAT and points in one campaign: the joined samples keep points.csv's pose column, so
    discover's folds keep a pose whole when its rows are not consecutive (each pose measured twice,
    the second pass after the first)."""
    arm = ap.load_arm()
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(samples_per_location=20, bar_placements=0))
    rng = np.random.default_rng(2)
    lim = arm.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (N_POSES, arm.n_axes))
    pose = np.tile(np.arange(N_POSES), 2)
    point = (ap.stylus_positions(arm, sim.truth, q[pose], frame="mt")
             + rng.normal(0.0, SIGMA, (len(pose), 3)))
    c = sim.campaign
    write_campaign(ap.Campaign(spat=c.spat, locations=c.locations, lengthbar=None, bar={},
                               points=PointLog(group=np.ones(len(pose), dtype=np.int64),
                                               q=q[pose], point=point,
                                               columns={"pose": 7.0 + pose})), tmp_path)
    campaign = read_campaign(tmp_path, arm=arm)
    joined = measurements(campaign, arm, True).samples
    n_spat = len(c.spat.q) if c.spat is not None else 0
    assert joined.n == n_spat + len(pose) and "pose" in joined.columns
    cal = ap.identify(campaign, arm, model="dh")
    lin = LinearScorer(cal, joined)
    point_groups = [g for g, centred in zip(lin.groups, lin.centred) if not centred]
    assert len(point_groups) == FOLDS
    rows = np.unique(np.concatenate(point_groups) // 3)  # samples in the folds, joined order
    # each sample's true pose: the drawn readouts it was read back as (file digits), else its own
    dist = np.linalg.norm(cal.q[rows][:, None] - q[None], axis=2)
    truth = np.where(dist.min(axis=1) < 1e-6, dist.argmin(axis=1), -1 - rows)
    assert np.sum(truth >= 0) == len(pose)
    at = {int(r): k for k, r in enumerate(rows)}
    local = [np.array([3 * at[int(r) // 3] + int(r) % 3 for r in g]) for g in point_groups]
    assert _split_poses(local, truth) == []
