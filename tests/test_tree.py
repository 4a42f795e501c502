"""Arms that are trees (several tools), the tool column of points.csv and joint-name readout columns."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import aacmm_pin as ap
from aacmm_pin import cli
from aacmm_pin.analyses.discovery import discover
from aacmm_pin.data.campaign import PointLog, read_readout_columns
from aacmm_pin.effects import calibrated as kinematics
from aacmm_pin.effects import compliance
from aacmm_pin.fit.measurements import check_points
from aacmm_pin.model.parameters import check_against_arm, parameters_from_dict
from aacmm_pin.model.samples import Samples

ROOT = Path(__file__).resolve().parents[1]
TORSO = ROOT / "urdf" / "torso.urdf"
SIGMA = 20e-6  # tracker noise per coordinate, m
HIDDEN = {"L2": 6e-6, "L4": 8e-6, "R2": 5e-6, "R4": 1e-5}
"""Hidden gravity compliance of the pitch axes (rad/(N m)): 30-60 um at the markers."""


@pytest.fixture(scope="module")
def torso() -> ap.Arm:
    return ap.load_arm(TORSO)


def _truth(arm: ap.Arm, seed: int, compliant: bool = True) -> ap.Parameters:
    """Nominal parameters with robot-sized DH and tool errors (0.3 mm, 0.03 deg), a tracker frame
    and (``compliant``) the hidden compliance."""
    rng = np.random.default_rng(seed)
    nominal = ap.Parameters.nominal(arm, 5.0)
    dh = {f.name: v + rng.normal(0.0, np.radians(0.03) if f.is_angle else 3e-4)
          for f, v in zip(arm.error_frames, nominal.dh.values())}
    tools = {k: v + rng.normal(0.0, 3e-4, 3) for k, v in nominal.tools.items()}
    ext = {f"compliance[A{arm.axis_names.index(n) + 1}]": [k] for n, k in HIDDEN.items()}
    return nominal.replace(dh=dh, tools=tools, rotation_abc=rng.normal(0.0, 0.2, 3),
                           translation=rng.uniform(-2.0, 2.0, 3),
                           extensions=ext if compliant else {})


def _campaign(arm: ap.Arm, truth: ap.Parameters, n: int, seed: int, sigma: float = SIGMA
              ) -> ap.Campaign:
    """Tracker points of both markers (alternate rows) at n random poses, one instrument frame."""
    rng = np.random.default_rng(seed)
    lim = arm.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))
    tool = np.where(np.arange(n) % 2, "right", "left")
    point = (ap.stylus_positions(arm, truth, q, frame="mt", tool=tool)
             + rng.normal(0.0, sigma, (n, 3)))
    return ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.ones(n, dtype=np.int64), q=q, point=point, tool=tool))


# ------------------------------------------------------------------------------- the model
def test_generator_writes_the_committed_torso():
    """urdf/make_torso.py writes exactly the committed urdf/torso.urdf and its sizes file."""
    spec = importlib.util.spec_from_file_location("make_torso", ROOT / "urdf" / "make_torso.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.make_urdf() == TORSO.read_text()
    assert module.make_sizes() == TORSO.with_name("torso.sizes.json").read_text()


def test_tree_axes_tools_and_error_frames(torso):
    """Axes depth-first over the tree (torso, left, right), two tools, 3 or 4 error frames per axis."""
    assert torso.axis_names == ["T1", *(f"L{i}" for i in range(1, 8)),
                                *(f"R{i}" for i in range(1, 8))]
    assert torso.tool_joints == ["tool_left", "tool_right"]
    assert torso.tool_names == ["left", "right"]
    assert torso.tool_unknowns[:3] == ["tool_left_x", "tool_left_y", "tool_left_z"]
    assert len(torso.error_names) == 54 and torso.off_chain == []
    np.testing.assert_array_equal(torso.tool_index(["right", "tool_left", "left"]), [1, 0, 0])
    with pytest.raises(ValueError, match="unknown tool 'head'.*left, right"):
        torso.tool_index(["head"])
    # the axis offset dth<k> turns about the next axis down its own branch (L2 and R2 about y)
    assert np.allclose(torso.error_frame("dth3").axis, [0, 1, 0])
    assert np.allclose(torso.error_frame("dth10").axis, [0, 1, 0])
    assert np.allclose(torso.error_frame("dth9").axis, [0, 0, 1])


def _two_branch_urdf(right_rpy: str) -> str:
    """A root error frame dth1, then two branches of one axis each (about z of a mount frame)."""
    def branch(side: str, rpy: str) -> str:
        return (f'<joint name="{side}_mount" type="fixed"><parent link="f1"/><child link="{side}0"/>'
                f'<origin xyz="0 0 0" rpy="{rpy}"/></joint><link name="{side}0"/>'
                f'<joint name="{side}_A" type="revolute"><parent link="{side}0"/>'
                f'<child link="{side}1"/><origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>'
                '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
                f'<link name="{side}1"/><joint name="tool_{side}" type="fixed">'
                f'<parent link="{side}1"/><child link="{side}_tip"/>'
                f'<origin xyz="0.1 0 0" rpy="0 0 0"/></joint><link name="{side}_tip"/>')
    return ('<?xml version="1.0"?><robot name="two"><link name="base"/>'
            '<joint name="dth1" type="fixed"><parent link="base"/><child link="f1"/></joint>'
            f'<link name="f1"/>{branch("left", "1.5707963267948966 0 0")}'
            f'{branch("right", right_rpy)}</robot>')


def test_axis_offset_turns_about_the_next_axis_of_every_branch(tmp_path):
    """dth before a branch point: the next axes (through the mounts' rotations) must agree."""
    path = tmp_path / "two.urdf"
    path.write_text(_two_branch_urdf("1.5707963267948966 0 0"))
    arm = ap.load_arm(path)
    np.testing.assert_allclose(arm.error_frame("dth1").axis, [0, -1, 0], atol=1e-15)
    path.write_text(_two_branch_urdf("0 0 0"))
    with pytest.raises(ap.ArmModelError, match="'dth1' sits before a branch"):
        ap.load_arm(path)


def test_single_tool_arms_keep_their_names(arm):
    """The default arm: one tool `tool`, unknowns tool_x/y/z, parameters.json with `tool` only."""
    assert arm.tool_joints == ["tool"] and arm.tool_names == ["tool"]
    assert arm.tool_unknowns == ["tool_x", "tool_y", "tool_z"]
    data = ap.Parameters.nominal(arm).to_dict()
    assert "tool" in data and "tools" not in data


def test_joints_on_no_tool_chain_are_held_fixed(tmp_path, torso):
    """A head joint on no tool's chain is not an axis and not in the models' configuration."""
    text = TORSO.read_text().replace("</robot>", (
        '  <joint name="head" type="revolute"><parent link="torso"/><child link="head_link"/>'
        '<origin xyz="0 0 0.8" rpy="0 0 0"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n'
        '  <link name="head_link"/>\n</robot>'))
    path = tmp_path / "torso_head.urdf"
    path.write_text(text)
    arm = ap.load_arm(path)
    assert arm.axis_names == torso.axis_names and arm.off_chain == ["head"]
    assert arm.runtime_model().nq == 15
    q = np.random.default_rng(0).uniform(-1, 1, (5, 15))
    params = ap.Parameters.nominal(arm)
    np.testing.assert_allclose(kinematics.predict(arm, params, q, tool="left"),
                               kinematics.predict(torso, ap.Parameters.nominal(torso), q,
                                                  tool="left"), atol=1e-15)


def test_tree_positions_match_pinocchio_runtime_model_of_the_urdf(torso):
    """Each tool's point equals Pinocchio's own model of torso.urdf (frames marker_*) to 1e-12 m."""
    model = pin.buildModelFromUrdf(str(TORSO))
    data = model.createData()
    rng = np.random.default_rng(3)
    q = rng.uniform(torso.joint_limits[:, 0], torso.joint_limits[:, 1], (40, 15))
    tool = rng.integers(0, 2, 40)
    ref = []
    for qi, k in zip(q, tool):
        pin.framesForwardKinematics(model, data, qi)  # URDF order = the arm's axis order
        ref.append(data.oMf[model.getFrameId(["marker_left", "marker_right"][k])].translation.copy())
    params = ap.Parameters.nominal(torso)
    for got in (kinematics.stylus_positions(torso, params, q, tool=tool),
                kinematics.predict(torso, params, q, tool=tool),
                kinematics.stylus_jacobians(torso, params, q, frame="r", tool=tool).position):
        np.testing.assert_allclose(got, np.array(ref), rtol=0, atol=1e-12)


def test_tree_identification_and_runtime_models_agree_off_nominal(torso):
    """With DH and tool errors, the identification model (every parameter a joint) and the
    runtime URDF agree for both tools to 1e-12 m; with no tool given a tree refuses."""
    params = _truth(torso, 1, compliant=False).replace(rotation_abc=np.zeros(3),
                                                       translation=np.zeros(3))
    q = np.random.default_rng(4).uniform(-2, 2, (30, 15))
    for tool in ("left", "right"):
        np.testing.assert_allclose(kinematics.stylus_positions(torso, params, q, tool=tool),
                                   kinematics.predict(torso, params, q, tool=tool), atol=1e-12)
    with pytest.raises(ValueError, match="2 tools"):
        kinematics.stylus_positions(torso, params, q)


def test_tree_gravity_is_pinocchios_in_axis_order(torso):
    """Samples.gravity is minus Pinocchio's generalized gravity of torso.urdf, axis by axis."""
    model = pin.buildModelFromUrdf(str(TORSO))
    data = model.createData()
    q = np.random.default_rng(5).uniform(-1.5, 1.5, (6, 15))
    ref = -np.array([pin.computeGeneralizedGravity(model, data, qi) for qi in q])
    got = Samples(torso, q).gravity
    np.testing.assert_allclose(got, ref, atol=1e-12)
    assert np.all(np.abs(got[:, 2]) > 0) and np.allclose(got[:, 0], 0, atol=1e-9)  # L2 / T1 yaw


# Central differences, h = 1e-6: truncation and round-off below 1e-8 (tests/test_kinematics.py)
H, ATOL = 1e-6, 1e-8


def test_tree_jacobian_matches_finite_differences(torso):
    """Each sample's Jacobian is its own tool's: readouts, DH, both tools' vectors, X0, translation
    against central differences; the other tool's and other arm's columns are exactly zero."""
    params = _truth(torso, 2, compliant=False)
    rng = np.random.default_rng(6)
    q = rng.uniform(-2, 2, (6, 15))
    tool = np.array([0, 1, 0, 1, 1, 0])
    jac = kinematics.stylus_jacobians(torso, params, q, frame="mt", tool=tool)

    def pos(p: ap.Parameters, qq: np.ndarray = q) -> np.ndarray:
        return kinematics.stylus_positions(torso, p, qq, frame="mt", tool=tool)

    for axis in range(15):
        dq = np.zeros(15)
        dq[axis] = H
        fd = (pos(params, q + dq) - pos(params, q - dq)) / (2 * H)
        np.testing.assert_allclose(jac.readouts[:, :, axis], fd, atol=ATOL)
    for k, name in enumerate(torso.error_names[::7]):
        col = torso.error_names.index(name)
        up = pos(params.replace(dh={**params.dh, name: params.dh[name] + H}))
        down = pos(params.replace(dh={**params.dh, name: params.dh[name] - H}))
        np.testing.assert_allclose(jac.dh[:, :, col], (up - down) / (2 * H), atol=ATOL)
    for t, joint in enumerate(torso.tool_joints):
        for c in range(3):
            step = np.zeros(3)
            step[c] = H
            up = pos(params.replace(tools={**params.tools, joint: params.tools[joint] + step}))
            down = pos(params.replace(tools={**params.tools, joint: params.tools[joint] - step}))
            np.testing.assert_allclose(jac.tool[:, :, 3 * t + c], (up - down) / (2 * H), atol=ATOL)
    for c in range(3):
        step = np.zeros(3)
        step[c] = H
        fd = (pos(params.replace(rotation_abc=params.rotation_abc + step))
              - pos(params.replace(rotation_abc=params.rotation_abc - step))) / (2 * H)
        np.testing.assert_allclose(jac.rotation[:, :, c], fd, atol=ATOL)
        np.testing.assert_allclose(jac.translation[:, :, c], np.eye(3)[:, [c] * 6].T, atol=1e-12)
    left = tool == 0
    assert np.all(jac.tool[left][:, :, 3:] == 0) and np.all(jac.tool[~left][:, :, :3] == 0)
    assert np.all(jac.readouts[left][:, :, 8:] == 0) and np.all(jac.readouts[~left][:, :, 1:8] == 0)
    assert np.abs(jac.tool[left][:, :, :3]).max() > 0.5  # a real rotation of the tool vector


# ------------------------------------------------------------------------------- parameters
def test_tree_parameters_json_and_calibrated_urdf(tmp_path, torso):
    """parameters.json holds `tools` by joint; the calibrated URDF carries each tool's vector."""
    truth = _truth(torso, 3, compliant=False)
    data = json.loads(json.dumps(truth.to_dict()))
    assert "tools" in data and "tool" not in data
    back = parameters_from_dict(data)
    check_against_arm(back, torso)
    for joint in torso.tool_joints:
        np.testing.assert_array_equal(back.tools[joint], truth.tools[joint])
    np.testing.assert_array_equal(back.tool, truth.tools["tool_left"])
    (tmp_path / "t.urdf").write_text(torso.urdf_string(truth.dh, tools=truth.tools))
    again = ap.load_arm(tmp_path / "t.urdf")
    for joint in torso.tool_joints:
        np.testing.assert_allclose(again.nominal_tools[joint], truth.tools[joint], atol=1e-15)
    with pytest.raises(ap.FileFormatError, match="give 'tools'"):
        check_against_arm(ap.Parameters(arm="torso", dh=truth.dh, tool=np.zeros(3)), torso)


def test_replace_keeps_tool_and_tools_consistent(torso):
    """replace(tools=) moves `tool` to the first tool; replace(tool=) changes the first tool."""
    nominal = ap.Parameters.nominal(torso)
    moved = nominal.replace(tools={"tool_left": np.ones(3), "tool_right": np.zeros(3)})
    np.testing.assert_array_equal(moved.tool, np.ones(3))
    again = moved.replace(tool=np.full(3, 2.0))
    np.testing.assert_array_equal(again.tools["tool_left"], np.full(3, 2.0))
    np.testing.assert_array_equal(again.tools["tool_right"], np.zeros(3))
    with pytest.raises(ValueError, match="differs from the first entry of tools"):
        ap.Parameters(arm="torso", dh={}, tool=np.zeros(3), tools={"tool_left": np.ones(3)})


def test_identify_command_writes_every_tool(tmp_path, torso):
    """`aacmm-pin identify` on a torso campaign: parameters.json holds both tools, and the
    calibrated URDF beside it carries them (it loads as the same tree)."""
    truth = _truth(torso, 5, compliant=False)
    ap.write_campaign(_campaign(torso, truth, 300, 5), tmp_path / "campaign")
    out = tmp_path / "cal"
    assert cli.main(["identify", str(tmp_path / "campaign"), "--model", "dh", "--arm", str(TORSO),
                     "--out", str(out)]) == 0
    params = ap.read_parameters(out)
    assert set(params.tools) == {"tool_left", "tool_right"}
    calibrated = ap.load_arm(params.arm)
    check_against_arm(params, calibrated)
    assert calibrated.axis_names == torso.axis_names
    for joint in torso.tool_joints:
        np.testing.assert_allclose(calibrated.nominal_tools[joint], params.tools[joint], atol=1e-15)
        # across the hand (x, y) the tool is identified (along it dz of axis 6 shares its length);
        # with errors of 0.3 mm, held gauge directions of the DH errors shift it by tens of um
        err = np.abs(params.tools[joint] - truth.tools[joint])[:2]
        assert np.all(err < 1e-4), err


# ------------------------------------------------------------------------------- files
def _write_points(folder: Path, header: list[str], rows: list[list[str]]) -> None:
    folder.mkdir(exist_ok=True)
    (folder / "points.csv").write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")


def _point_rows(tools: list[str]) -> tuple[list[str], list[list[str]]]:
    header = ["tool", *(f"q{i}_deg" for i in range(1, 16)), "x_mm", "y_mm", "z_mm"]
    rows = [[t, *(str(5 * i + k) for i in range(15)), str(k), str(2 * k), str(k * k)]
            for k, t in enumerate(tools)]
    return header, rows


def test_tool_column_is_read_and_written(tmp_path, torso):
    """The tool column goes through write_campaign/read_campaign unchanged."""
    campaign = _campaign(torso, _truth(torso, 0), 10, 0)
    ap.write_campaign(campaign, tmp_path)
    back = ap.read_campaign(tmp_path, arm=torso).points
    assert back is not None and back.tool is not None
    assert back.tool.tolist() == ["left", "right"] * 5
    assert ap.read_campaign(tmp_path).points.tool.tolist() == ["left", "right"] * 5


def test_unknown_tool_is_named_with_file_line_and_column(tmp_path, torso):
    """An unknown tool name is a points.csv line/column error listing the arm's tools."""
    _write_points(tmp_path, *_point_rows(["left", "right", "head", "left"]))
    with pytest.raises(ap.CampaignFormatError) as info:
        ap.read_campaign(tmp_path, arm=torso)
    assert "points.csv:4: column 'tool': unknown tool 'head'; the arm's tools: left, right" in str(
        info.value)
    campaign = ap.read_campaign(tmp_path)  # without the arm: read, checked at identification
    with pytest.raises(ap.IdentificationError, match=r"points.csv: line 4: column 'tool': unknown "
                                                     r"tool 'head'.*left, right"):
        check_points(campaign, torso)


def test_tool_column_is_required_for_several_tools(tmp_path, torso, arm):
    """Without a tool column: an error for the torso (file, line 1, column), fine for one tool."""
    header, rows = _point_rows(["left"] * 4)
    _write_points(tmp_path, header[1:], [r[1:] for r in rows])
    with pytest.raises(ap.CampaignFormatError, match=r"points.csv:1: column 'tool': missing column: "
                                                     r"the arm has 2 tools \(left, right\)"):
        ap.read_campaign(tmp_path, arm=torso)
    with pytest.raises(ap.IdentificationError, match="column 'tool': missing"):
        check_points(ap.read_campaign(tmp_path), torso)
    seven = tmp_path / "seven"
    _write_points(seven, ["tool", *(f"q{i}_deg" for i in range(1, 8)), "x_mm", "y_mm", "z_mm"],
                  [["tool", *(str(i + k) for i in range(7)), str(k), str(k * k), str(-k)]
                   for k in range(4)])
    assert ap.read_campaign(seven, arm=arm).points is not None  # the single tool may be named


def test_joint_name_columns_round_trip_in_any_order(tmp_path, torso):
    """<joint>_deg columns in shuffled order read back as the q columns, in axis order."""
    campaign = _campaign(torso, _truth(torso, 0), 8, 1)
    ap.write_campaign(campaign, tmp_path / "q")
    lines = (tmp_path / "q" / "points.csv").read_text().splitlines()
    header = lines[0].split(",")
    named = [f"{torso.axis_names[int(h[1:-4]) - 1]}_deg" if h.startswith("q") else h
             for h in header]
    order = np.random.default_rng(0).permutation(len(header))
    rows = [[line.split(",")[k] for k in order] for line in lines[1:]]
    _write_points(tmp_path / "named", [named[k] for k in order], rows)
    q_back = ap.read_campaign(tmp_path / "q", arm=torso).points.q
    named_back = ap.read_campaign(tmp_path / "named", arm=torso).points.q
    np.testing.assert_array_equal(named_back, q_back)
    np.testing.assert_allclose(named_back, campaign.points.q, atol=1e-11)
    # predict's input too
    q, _, _ = read_readout_columns(tmp_path / "named" / "points.csv", torso)
    np.testing.assert_array_equal(q, q_back)
    with pytest.raises(ap.CampaignFormatError, match=r"column '\w+_deg': unknown columns .*L1_deg"
                                                     r".*only with the arm"):
        ap.read_campaign(tmp_path / "named")


def test_mixed_and_missing_joint_name_columns_are_errors(tmp_path, torso):
    """Mixing q<n>_deg with <joint>_deg, or leaving out an axis, names the file and column."""
    header, rows = _point_rows(["left"] * 3)
    mixed = [f"{torso.axis_names[0]}_deg" if h == "q1_deg" else h for h in header]
    _write_points(tmp_path / "mixed", mixed, rows)
    with pytest.raises(ap.CampaignFormatError) as info:
        ap.read_campaign(tmp_path / "mixed", arm=torso)
    assert "points.csv:1: column 'q2_deg': mixes q<n>_deg and joint-name readout columns" in str(
        info.value) and len(info.value.problems) == 1
    named = [f"{torso.axis_names[int(h[1:-4]) - 1]}_deg" if h.startswith("q") else h
             for h in header]
    drop = named.index("R3_deg")
    _write_points(tmp_path / "missing", named[:drop] + named[drop + 1:],
                  [r[:drop] + r[drop + 1:] for r in rows])
    with pytest.raises(ap.CampaignFormatError) as info:
        ap.read_campaign(tmp_path / "missing", arm=torso)
    assert "points.csv:1: column 'R3_deg': missing column: joint-name readout columns" in str(
        info.value)


def test_axes_command_prints_tools(capsys):
    """`aacmm-pin axes torso.urdf` lists the 15 readout columns and both tools."""
    assert cli.main(["axes", str(TORSO)]) == 0
    out = capsys.readouterr().out
    assert "15 axes" in out and "q15_deg joint R7" in out and "q2_deg  joint L1" in out
    assert "left         joint tool_left" in out and "tool_right_x" in out


def test_predict_command_reads_joint_names_and_tools(tmp_path, torso, capsys):
    """`aacmm-pin predict` on a tree: <joint>_deg columns and a tool column give each row's tool
    point (as predict()); without the tool column it stops with file, line and column."""
    params = _truth(torso, 4, compliant=False).replace(arm=str(TORSO))
    ap.write_parameters(params, tmp_path / "parameters.json")
    rng = np.random.default_rng(7)
    q = rng.uniform(-1.5, 1.5, (6, 15))
    tools = ["left", "right", "right", "left", "left", "right"]
    order = rng.permutation(15)
    header = ["tool", *(f"{torso.axis_names[k]}_deg" for k in order)]
    rows = [[t, *(f"{np.degrees(qi[k]):.12f}" for k in order)] for t, qi in zip(tools, q)]
    (tmp_path / "q.csv").write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")
    out = tmp_path / "points.csv"
    assert cli.main(["predict", str(tmp_path), str(tmp_path / "q.csv"), "--out", str(out)]) == 0
    got = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(-3, -2, -1)) * 1e-3
    np.testing.assert_allclose(got, kinematics.predict(torso, params, q, tool=tools), atol=1e-11)
    (tmp_path / "q.csv").write_text("\n".join(",".join(r[1:]) for r in [header, *rows]) + "\n")
    assert cli.main(["predict", str(tmp_path), str(tmp_path / "q.csv"), "--out", str(out),
                     "--force"]) == 2
    assert "q.csv:1: column 'tool': missing column" in capsys.readouterr().err


# ------------------------------------------------------------------------------- round trip
def _round_trip(torso: ap.Arm, seed: int, n: int) -> tuple[np.ndarray, list[int], tuple[float, ...]]:
    """Identify and discover on simulated points; return z-scores, named axes, held-out RMS."""
    truth = _truth(torso, seed)
    campaign = _campaign(torso, truth, n, seed)
    axes = sorted(torso.axis_names.index(name) + 1 for name in HIDDEN)
    cal = ap.identify(campaign, torso, model="dh", extensions=tuple(compliance(a) for a in axes))
    assert cal.success
    assert abs(cal.fit_rms / SIGMA - 1) < 0.1  # 3n coordinates less ~70 parameters
    equivalent, _ = cal.equivalent(truth)
    u = cal.unknowns
    std = np.sqrt(np.diag(cal.covariance))[:len(u.names)]
    z = ((u.vector(cal.parameters) - u.vector(equivalent)) / std)[cal.identifiable]
    names = np.array(u.names)[cal.identifiable]
    assert all(f"compliance[A{a}].k" in names for a in axes)  # the hidden terms are identified
    # both tools' vectors are estimated (along the hand, dz<k> of axis 6 carries the same length)
    assert {f"tool_{s}_{c}" for s in ("left", "right") for c in "xyz"} <= set(u.names)
    assert {"tool_left_x", "tool_left_y", "tool_right_x", "tool_right_y"} <= set(names)
    found = discover(campaign, torso, "dh")
    named = sorted(a for step in found.steps if step.effect == "compliance" for a in step.axes)
    assert [s.effect for s in found.steps] == ["compliance"]
    held = (found.heldout_rms[0], found.heldout_rms[-1])
    return z, named, held


def test_torso_round_trip_identify_and_discover(torso):
    """Two markers, one tracker frame: the joint DH + compliance fit recovers the truth within
    |z| < 4.5 (P(any of ~60 > 4.5) ~ 4e-4), and discovery names compliance on exactly the hidden
    axes, the held-out RMS falling to the noise."""
    z, named, (before, after) = _round_trip(torso, 0, 600)
    assert z.size >= 50 and np.all(np.abs(z) < 4.5), z.round(2)
    assert named == sorted(torso.axis_names.index(name) + 1 for name in HIDDEN)
    assert before > 1.3 * SIGMA and after < 1.1 * SIGMA


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_torso_round_trip_seeds(torso, seed):
    """The torso round trip on more seeds."""
    z, named, (before, after) = _round_trip(torso, seed, 600)
    assert z.size >= 50 and np.all(np.abs(z) < 4.5), z.round(2)
    assert named == sorted(torso.axis_names.index(name) + 1 for name in HIDDEN)
    assert before > 1.3 * SIGMA and after < 1.1 * SIGMA
