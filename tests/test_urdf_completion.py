"""A robot's own URDF as it ships (ROS-style, tool0, no error frames): completed in memory."""

from __future__ import annotations

import pickle
import re
import shutil

import numpy as np
import pinocchio as pin
import pytest
from lxml import etree

from aacmm_pin.cli import main
from aacmm_pin.errors import ArmModelError
from aacmm_pin.model.arm import Arm, load_arm
from aacmm_pin.model.urdf_completion import Completion, add_error_frames, add_tool_joint
from aacmm_pin.model.urdf_tree import read_urdf
from tests.helpers import ROOT, SHARED

ROS_UR5 = SHARED / "robots" / "ur5-ros-industrial" / "ur5_robot.urdf"
AXES = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
        "wrist_2_joint", "wrist_3_joint"]

pytestmark = pytest.mark.skipif(not ROS_UR5.is_file(), reason="needs ../shared/robots")


def _names(path) -> tuple[set[str], set[str]]:
    root = etree.parse(str(path)).getroot()
    return ({e.get("name") for e in root.findall("link")},
            {e.get("name") for e in root.findall("joint")})


def test_ros_urdf_loads_with_tool0_and_added_error_frames():
    """The ROS UR5 loads unedited: its six joints are the axes, the tool hangs off tool0, and the
    note names what was added in one line."""
    arm = load_arm(ROS_UR5)
    assert arm.axis_names == AXES
    assert arm.tool_joints == ["tool"] and arm.tool_links == ["tool0_point"]
    assert np.allclose(arm.nominal_tool, 0.0)
    assert arm.completion.tool_frame == "tool0"
    assert arm.error_names == list(arm.completion.error_frames)
    assert all(re.fullmatch(r"(dx|dy|dz|a|b|c)[2-6]", n) for n in arm.error_names)
    assert arm.note is not None and "\n" not in arm.note
    assert arm.note.startswith("ur5_robot.urdf has no error frames: added 20")
    assert "shoulder_pan_joint ... wrist_3_joint" in arm.note and "tool0 (joint 'tool')" in arm.note


def test_completion_leaves_every_link_of_the_user_where_the_urdf_puts_it():
    """At the nominal values every original link of the completed model is placed as Pinocchio
    places it from the unedited file, for random joint angles; the tool point is tool0."""
    arm = load_arm(ROS_UR5)
    original = pin.buildModelFromUrdf(str(ROS_UR5))
    model = arm.runtime_model()
    data, odata = model.createData(), original.createData()
    rng = np.random.default_rng(0)
    links, _ = _names(ROS_UR5)
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, 6)
        pin.framesForwardKinematics(model, data, q)
        pin.framesForwardKinematics(original, odata, q)  # same joint order: one chain
        for link in links:
            a = data.oMf[model.getFrameId(link)]
            b = odata.oMf[original.getFrameId(link)]
            assert np.allclose(a.homogeneous, b.homogeneous, atol=1e-12), link
        assert np.allclose(data.oMf[model.getFrameId("tool0_point")].translation,
                           odata.oMf[original.getFrameId("tool0")].translation, atol=1e-12)


def _rank(arm: Arm) -> int:
    """Rank of the stacked point Jacobian w.r.t. X0, the error frames and the tool (30 poses)."""
    ident = arm.identification
    data = ident.model.createData()
    cols = np.concatenate([ident.base_idx, ident.error_idx, ident.tool_idx])
    rng = np.random.default_rng(1)
    rows = []
    for _ in range(30):
        q = np.zeros(ident.model.nq)
        q[ident.axis_idx] = rng.uniform(-np.pi, np.pi, arm.n_axes)
        jac = pin.computeFrameJacobian(ident.model, data, q, ident.stylus_frame,
                                       pin.LOCAL_WORLD_ALIGNED)
        rows.append(jac[:3, cols])
    return int(np.linalg.matrix_rank(np.vstack(rows), tol=1e-9))


def test_the_minimal_set_is_as_complete_as_six_per_axis():
    """Leaving out the error frames that other parameters' motions repeat loses nothing: the
    point Jacobian over X0, error frames and tool has the rank of six error frames per axis."""
    urdf, _ = add_tool_joint(read_urdf(ROS_UR5))
    bare = Arm(urdf, ROS_UR5, "ros")
    full = Arm(add_error_frames(urdf, bare.axis_names, minimal=False)[0], ROS_UR5, "full")
    minimal = load_arm(ROS_UR5)
    assert len(full.error_names) == 36 and len(minimal.error_names) == 20
    assert _rank(minimal) == _rank(full) == 25  # identify's "25 parameters determined" on both


def test_pickled_arm_reloads_with_its_tool_frame_and_sizes(tmp_path):
    """An arm given a tool frame and a sizes file pickles to an identical arm (workers)."""
    sizes = tmp_path / "mine.json"
    shutil.copy(ROOT / "urdf" / "ur5.sizes.json", sizes)
    arm = load_arm(ROS_UR5, tool_frame="ee_link", sizes=sizes)
    again = pickle.loads(pickle.dumps(arm))
    assert again.tool_links == ["ee_link_point"] and again.completion == arm.completion
    assert again.error_names == arm.error_names and again.sizes == arm.sizes
    assert again.sizes_file == sizes and arm.sizes.dh_length == 5e-4


@pytest.mark.parametrize(("edit", "kwargs", "message"), [
    (lambda t: t.replace('name="tool0"', 'name="flange"').replace('link="tool0"', 'link="flange"'),
     {}, r"no link 'tool0': name the link .* --tool-frame LINK \(candidate links .*: ee_link, "
         r"flange\)"),
    (None, {"tool_frame": "nope"}, r"tool frame 'nope' is no link of the URDF \(candidate"),
    (None, {"tool_frame": "base"}, r"nothing to calibrate: no revolute joint between the root "
                                   r"link and the tool frame 'base'"),
    (lambda t: t.replace('name="ee_link"', 'name="a2_frame"').replace('link="ee_link"',
                                                                       'link="a2_frame"'),
     {}, r"cannot add the error frames: the URDF has a link 'a2_frame' already"),
    (lambda t: t.replace('name="ee_fixed_joint" type="fixed"', 'name="tool" type="fixed"'),
     {"tool_frame": "tool0"}, r"tool frame 'tool0' given, but the URDF names its tool joint"),
])
def test_refusals_name_the_file_in_one_line(tmp_path, edit, kwargs, message):
    """A URDF without tool0, an unknown link, a tool frame with no axis before it, a name clash
    and a tool frame beside the URDF's own tool joint are refused in one line naming the file."""
    path = tmp_path / "robot.urdf"
    text = ROS_UR5.read_text()
    path.write_text(edit(text) if edit else text)
    with pytest.raises(ArmModelError) as info:
        load_arm(path, **kwargs)
    text = str(info.value)
    assert "\n" not in text and str(path) in text and re.search(message, text), text


def test_axes_writes_the_error_frames_and_the_file_needs_no_option(tmp_path, capsys):
    """``axes URDF --write-error-frames OUT`` writes the URDF the package uses: it loads with no
    option and adds nothing, keeps every link and joint name and its package:// meshes."""
    out = tmp_path / "ur5_errors.urdf"
    assert main(["axes", str(ROS_UR5), "--write-error-frames", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.count("has no error frames") == 1 and f"wrote {out}" in printed
    arm, original = load_arm(ROS_UR5), load_arm(out)
    assert original.note is None and original.completion == Completion()
    assert original.error_names == arm.error_names and original.axis_names == AXES
    links, joints = _names(ROS_UR5)
    new_links, new_joints = _names(out)
    assert links < new_links and joints < new_joints
    meshes = [e.get("filename") for e in etree.parse(str(out)).iter("mesh")]
    assert meshes and all(m.startswith("package://example-robot-data/") for m in meshes)


def test_cli_tool_frame_is_passed_and_a_wrong_one_refused_in_one_line(capsys):
    """``--tool-frame`` reaches the arm (``axes`` lists the point on ee_link); an unknown link is
    one error line naming the file, exit status 2."""
    assert main(["axes", str(ROS_UR5), "--tool-frame", "ee_link"]) == 0
    assert "link ee_link_point" in capsys.readouterr().out
    assert main(["axes", str(ROS_UR5), "--tool-frame", "nope"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if "still working" not in line]
    assert len(err) == 1 and "ur5_robot.urdf" in err[0] and "'nope' is no link" in err[0]
