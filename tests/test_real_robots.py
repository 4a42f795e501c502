"""Public UR5 laser-tracker data (issue 25): the discovered model's test error, pose-grouped folds."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from tests.helpers import SHARED

ROOT = Path(__file__).resolve().parents[1]
DATA = SHARED / "real-data" / "jacobi2025-laser-tracker"
UR5_DISCOVERED_MM = 0.060
"""Issue 25's bound on the UR5's discovered model, mean error on its 20 random poses, mm."""


@pytest.mark.slow  # about 8 s CPU: identify, discover and a refit per step
def test_ur5_discovered_model_on_the_random_poses(tmp_path, monkeypatch):
    """Example 03's UR5: the model discover finds (k-fold over whole poses) predicts the 20 random
    test poses within 0.060 mm, better than DH's."""
    spec = importlib.util.spec_from_file_location("example03", ROOT / "examples" /
                                                  "03_laser_tracker_ur5_wam.py")
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, example)  # its dataclasses look it up
    spec.loader.exec_module(example)
    rows = example.ur5(DATA, tmp_path)
    dh, found = rows[1], rows[-1]
    assert dh.model == "DH" and found.model.startswith("+ ")
    assert found.test_mm <= UR5_DISCOVERED_MM < dh.test_mm
    # the exported calibration (maps and extension terms) through the runtime object, which reads
    # compact.urdf and compact.json, reproduces predict of the full calibration to 1e-9 m
    import aacmm_pin as ap

    folder = ap.read_calibration(tmp_path / "ur5_discovered")
    assert folder.parameters.encoder_maps and folder.parameters.extensions
    q = ap.read_campaign(tmp_path / "ur5_random").points.q
    reference = ap.predict(ap.load_arm(folder.parameters.arm), folder.parameters, q)
    runtime = ap.load_calibrated(tmp_path / "ur5_discovered")
    assert not runtime.arm.error_frames
    assert abs(runtime.position(q) - reference).max() < 1e-9
    # the URDF alone's loss written by the export = plain Pinocchio of compact.urdf (readouts as
    # joint angles) against predict with the grid's samples (row order: the backlash's motion)
    import json

    import numpy as np
    import pinocchio as pin

    from aacmm_pin.model.samples import Samples

    grid = ap.read_campaign(tmp_path / "ur5_grid").points
    model = pin.buildModelFromUrdf(str(tmp_path / "ur5_discovered" / "compact.urdf"))
    data, frame = model.createData(), model.getFrameId(runtime.tool_links[0])
    alone = []
    for qi in grid.q:
        pin.framesForwardKinematics(model, data, qi)
        alone.append(data.oMf[frame].translation.copy())
    full_arm = ap.load_arm(folder.parameters.arm)
    full = ap.predict(full_arm, folder.parameters, grid.q, Samples.of_log(full_arm, grid))
    d = np.linalg.norm(np.array(alone) - full, axis=1) / 1e-6  # um
    entry = json.loads((tmp_path / "ur5_discovered" / "report.json").read_text())["urdf_alone_loss_um"]
    assert entry["n_poses"] == len(d)
    assert entry["rms"] == pytest.approx(np.sqrt(np.mean(d ** 2)), abs=1e-3)
    assert entry["max"] == pytest.approx(d.max(), abs=1e-3) and d.max() > 100  # maps, backlash
    assert f"alone is {entry['rms']:.3g} um RMS" in (tmp_path / "ur5_discovered" /
                                                     "compact.urdf").read_text()


ROS_UR5 = SHARED / "robots" / "ur5-ros-industrial" / "ur5_robot.urdf"
"""example-robot-data's UR5 URDF as robotics stacks ship it (tool0, no error frames)."""


@pytest.mark.skipif(not ROS_UR5.is_file(), reason="needs ../shared/robots")
def test_ros_urdf_calibrates_as_the_embedded_ur5(tmp_path, capsys):
    """The unedited ROS UR5 URDF (tool frame tool0, error frames added in memory, the UR5's sizes
    by --sizes) calibrated by DH from the tracker grid is within 5 % of --arm ur5 on the 20 random
    poses; its calibrated.urdf keeps every original link and joint name and its sizes."""
    import json

    from lxml import etree

    from aacmm_pin.cli import main
    from aacmm_pin.model.arm import load_arm

    grid, test = tmp_path / "grid", tmp_path / "random"
    for source, out in (("grid", grid), ("random", test)):
        assert main(["import-points", str(DATA / "UR5" / f"3D_UR5_uncalibrated_{source}_cleaned.csv"),
                     "--out", str(out)]) == 0
    means = {}
    for name, arm in (("ros", [str(ROS_UR5), "--sizes", str(ROOT / "urdf" / "ur5.sizes.json")]),
                      ("ur5", ["ur5"])):
        assert main(["identify", str(grid), "--arm", *arm, "--model", "dh",
                     "--out", str(tmp_path / name)]) == 0
        assert main(["validate", str(tmp_path / name), str(test),
                     "--json", str(tmp_path / f"{name}.json")]) == 0
        means[name] = json.loads((tmp_path / f"{name}.json").read_text())["points"]["mean_mm"]
    assert capsys.readouterr().out.count("ur5_robot.urdf has no error frames") == 1
    assert abs(means["ros"] - means["ur5"]) <= 0.05 * means["ur5"], means
    names = {}
    for path in (ROS_UR5, tmp_path / "ros" / "calibrated.urdf"):
        root = etree.parse(str(path)).getroot()
        names[path.name] = {(e.tag, e.get("name")) for e in root if e.tag in ("link", "joint")}
    assert names["ur5_robot.urdf"] < names["calibrated.urdf"]
    calibrated = load_arm(tmp_path / "ros" / "calibrated.urdf")  # needs no option
    assert calibrated.note is None and calibrated.tool_joints == ["tool"]
    assert calibrated.sizes == load_arm("ur5").sizes  # the folder carries the sizes given


WAM_GRID = DATA / "WAM" / "3D_WAM_uncalibrated_grid_cleaned.csv"


@pytest.mark.skipif(not WAM_GRID.is_file(), reason="needs ../shared/real-data")
def test_wam_discovered_model_holds_on_refits(tmp_path, capsys):
    """Issue 40: on the WAM's grid (residual 65x the tracker's stated noise) default discover checks
    each step by 5-fold refits; the model it ends with, refitted on each 4/5 of the poses, predicts
    the fifth better than DH (the linearised score alone ended at 2.16 mm against DH's 2.12 mm)."""
    import json

    import aacmm_pin as ap
    from aacmm_pin.analyses.refit_check import refit_error
    from aacmm_pin.cli import main

    grid = tmp_path / "grid"
    assert main(["import-points", str(WAM_GRID), "--out", str(grid)]) == 0
    assert main(["discover", str(grid), "--arm", "wam7", "--out", str(tmp_path / "d")]) == 0
    assert "refits: the fit's residual" in capsys.readouterr().out
    report = json.loads((tmp_path / "d" / "discovery.json").read_text())
    errors = report["refits"]["error_um"]
    assert len(errors) == len(report["steps"]) + 1 and report["steps"]
    assert all(b < a for a, b in zip(errors, errors[1:]))  # every step taken lowered it
    # the final model's refit error recomputed from discovery.json's final model, against DH's
    arm, campaign = ap.load_arm("wam7"), ap.read_campaign(grid)
    final = ap.effects.ModelSpec(tuple(ap.effects.term_from_key(k)
                                       for k in report["final"]["extensions"]),
                                 tuple(report["final"]["map_axes"]))
    dh, found = refit_error(campaign, arm), refit_error(campaign, arm, final)
    assert found == pytest.approx(errors[-1] * 1e-6, rel=1e-6)
    assert found < dh
