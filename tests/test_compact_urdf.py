"""The compact URDF (error frames folded), compact.json and the URDF-alone loss of an export."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import aacmm_pin as ap
from aacmm_pin.cli import main
from aacmm_pin.effects.builtin.compliance import compliance
from aacmm_pin.model.arm import ERROR_FRAME_PATTERN
from aacmm_pin.model.compact_urdf import compact_urdf
from aacmm_pin.model.encoder_map import EncoderMap
from aacmm_pin.model.samples import Samples
from aacmm_pin.model.urdf_tree import read_urdf
from aacmm_pin.outputs.export import compact_parameters


def _random_values(arm: ap.Arm, rng: np.random.Generator
                   ) -> tuple[dict[str, float], dict[str, np.ndarray]]:
    """Random DH values (1 mm, 0.5 deg) and tool vectors (nominal + 10 mm)."""
    dh = {f.name: rng.normal(0, 1e-2 if f.is_angle else 1e-3) for f in arm.error_frames}
    tools = {t: v + rng.normal(0, 1e-2, 3) for t, v in arm.nominal_tools.items()}
    return dh, tools


def _tool_positions(path: Path, arm: ap.Arm, angles: np.ndarray) -> np.ndarray:
    """Every tool's position (n_tools, N, 3), m, by plain Pinocchio of a URDF file, joints by name."""
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    idx = [model.joints[model.getJointId(n)].idx_q for n in arm.axis_names]
    frames = [model.getFrameId(link) for link in arm.tool_links]
    out = np.empty((len(frames), len(angles), 3))
    for i, row in enumerate(angles):
        q = pin.neutral(model)
        q[idx] = row
        pin.framesForwardKinematics(model, data, q)
        for k, fid in enumerate(frames):
            out[k, i] = data.oMf[fid].translation
    return out


@pytest.mark.parametrize("name", ["aacmm7", "ur5", "torso"])
def test_compact_urdf_keeps_every_tool_position(name: str, tmp_path: Path) -> None:
    """Plain Pinocchio of the compact URDF gives the error-frame URDF's tool positions to 1e-12 m."""
    arm = ap.load_arm(name)
    rng = np.random.default_rng(7)
    dh, tools = _random_values(arm, rng)
    tree = arm.urdf_tree(dh, tools=tools)
    (tmp_path / "full.urdf").write_text(tree.xml())
    (tmp_path / "compact.urdf").write_text(compact_urdf(tree).xml())
    angles = rng.uniform(-np.pi, np.pi, (50, arm.n_axes))
    full = _tool_positions(tmp_path / "full.urdf", arm, angles)
    compact = _tool_positions(tmp_path / "compact.urdf", arm, angles)
    assert np.abs(compact - full).max() < 1e-12


@pytest.mark.parametrize("name", ["aacmm7", "ur5"])
def test_compact_urdf_keeps_the_users_names_only(name: str) -> None:
    """Its joints and links are the original's minus the error-frame joints and their links."""
    arm = ap.load_arm(name)
    original = read_urdf(arm.source)
    errors = [j for j in original.joints() if j.type == "fixed" and ERROR_FRAME_PATTERN.match(j.name)]
    assert len(errors) == len(arm.error_frames) > 0
    compact = compact_urdf(arm.urdf_tree(*_random_values(arm, np.random.default_rng(1))[:1]))
    error_names = {j.name for j in errors}
    assert [j.name for j in compact.joints()] == [j.name for j in original.joints()
                                                  if j.name not in error_names]
    assert compact.links == [n for n in original.links if n not in {j.child for j in errors}]
    assert set(arm.tool_joints) <= {j.name for j in compact.joints()}  # tools are no error frames
    text = compact.xml()
    for tag in ("<visual", "<material", "<inertial", "<limit"):  # the rest as written
        assert text.count(tag) == arm.urdf_string().count(tag)


URDF_WITH_A_FULL_ERROR_LINK = """<?xml version="1.0"?>
<robot name="r">
  <link name="base"/>
  <joint name="A1" type="revolute">
    <parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l1">
    <inertial><origin xyz="0.1 0 0" rpy="0 0 0"/><mass value="2"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial>
  </link>
  <joint name="c12" type="fixed">
    <parent link="l1"/><child link="c12_frame"/><origin xyz="0 0 0" rpy="0 0 0.3"/>
  </joint>
  <link name="c12_frame">
    <visual><origin xyz="0.2 0 0" rpy="0 0 0"/><geometry><box size="0.1 0.1 0.1"/></geometry></visual>
    <inertial><origin xyz="0 0.05 0.01" rpy="0.1 0.2 0.3"/><mass value="1.5"/>
      <inertia ixx="0.004" ixy="0.0001" ixz="0" iyy="0.005" iyz="0" izz="0.006"/></inertial>
  </link>
  <joint name="A2" type="revolute">
    <parent link="c12_frame"/><child link="l2"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l2">
    <inertial><origin xyz="0.1 0 0" rpy="0 0 0"/><mass value="1"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="stylus"/>
    <origin xyz="0.1 0 0"/></joint>
  <link name="stylus"/>
</robot>
"""


def test_an_error_link_with_inertia_and_visuals_hands_them_to_its_parent(tmp_path: Path) -> None:
    """Its inertia joins the parent's (mass matrix and centre of mass kept), its visual moves."""
    path = tmp_path / "r.urdf"
    path.write_text(URDF_WITH_A_FULL_ERROR_LINK)
    compact = compact_urdf(read_urdf(path))
    assert "c12_frame" not in compact.links and "c12" not in [j.name for j in compact.joints()]
    models = [pin.buildModelFromXML(text) for text in (path.read_text(), compact.xml())]
    q = np.array([0.4, -0.7])
    values = []
    for model in models:
        data = model.createData()
        values.append((pin.crba(model, data, q).copy(), pin.centerOfMass(model, data, q).copy(),
                       pin.computeTotalMass(model)))
    assert np.abs(values[0][0] - values[1][0]).max() < 1e-12
    assert np.abs(values[0][1] - values[1][1]).max() < 1e-12
    assert values[0][2] == pytest.approx(values[1][2], abs=1e-12)
    visual = [v for v in compact.root.iter("visual")]
    assert len(visual) == 1 and visual[0].getparent().get("name") == "l1"
    xyz = np.array([float(v) for v in visual[0].find("origin").get("xyz").split()])
    c, s = np.cos(0.3), np.sin(0.3)
    assert np.abs(xyz - [0.2 * c, 0.2 * s, 0]).max() < 1e-15  # Rz(0.3) (0.2, 0, 0)


@pytest.mark.parametrize("name", ["aacmm7", "ur5", "torso"])
def test_compact_parameters_predict_as_the_full_ones(name: str, tmp_path: Path) -> None:
    """The compact URDF with its parameters (maps, compliance, no DH) predicts as the full URDF.

    Both arms loaded from their URDFs with the calibrated values, as a folder's parameters files
    name them (compliance's gravity torques come from the arm's own geometry).
    """
    arm = ap.load_arm(name)
    rng = np.random.default_rng(3)
    dh, tools = _random_values(arm, rng)
    nominal = ap.Parameters.nominal(arm)
    maps = {a: EncoderMap(rng.normal(0, 1e-4, nominal.map(a).nodes.size), nominal.step_deg)
            for a in range(1, arm.n_axes + 1)}
    vectors = {"tools": tools} if arm.n_tools > 1 else {"tool": tools[arm.tool_joints[0]]}
    params = nominal.replace(dh=dh, encoder_maps=maps, **vectors,
                             extensions={compliance(2).key: np.array([2e-5])})
    tree = arm.urdf_tree(dh, tools=tools)
    compact = compact_urdf(tree)
    (tmp_path / "full.urdf").write_text(tree.xml())
    (tmp_path / "compact.urdf").write_text(compact.xml())
    full = ap.load_arm(tmp_path / "full.urdf")
    small = ap.load_arm(tmp_path / "compact.urdf", error_frames=False)
    assert small.error_frames == [] and small.axis_names == arm.axis_names
    q = rng.uniform(-np.pi, np.pi, (40, arm.n_axes))
    runtime = ap.CalibratedArm(small, compact_parameters(params, arm, compact))
    for tool in range(arm.n_tools):
        reference = ap.predict(full, params, q, tool=tool)
        assert np.abs(ap.predict(small, compact_parameters(params, arm, compact), q, tool=tool)
                      - reference).max() < 1e-9
        assert np.abs(runtime.position(q, tool=tool) - reference).max() < 1e-9
        assert np.abs(runtime.position(q[7], tool=tool) - reference[7]).max() < 1e-9


@pytest.fixture(scope="module")
def with_compliance(small_cal: ap.Calibration) -> ap.Calibration:
    """The small calibration (maps) with a compliance term on A2."""
    return dataclasses.replace(small_cal, parameters=small_cal.parameters.replace(
        extensions={compliance(2).key: np.array([2e-5])}))


def test_compact_json_predicts_as_parameters_json(arm: ap.Arm, small_sim: ap.Simulation,
                                                  with_compliance: ap.Calibration,
                                                  tmp_path: Path) -> None:
    """A folder's compact.json (with its compact.urdf) predicts as its parameters.json to 1e-9 m."""
    folder = ap.write_calibration(with_compliance, arm, tmp_path / "cal", campaign=small_sim.campaign)
    full, compact = ap.read_calibration(folder), ap.read_calibration(folder / "compact.json")
    assert compact.parameters.dh == {} and compact.parameters.extensions.keys() == {"compliance[A2]"}
    compact_arm = ap.load_arm(compact.parameters.arm, error_frames=False)
    full_arm = ap.load_arm(full.parameters.arm)
    compact.check(compact_arm)
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (30, 7))
    reference = ap.predict(full_arm, full.parameters, q)
    assert np.abs(ap.predict(compact_arm, compact.parameters, q) - reference).max() < 1e-9
    runtime = ap.load_calibrated(folder)  # through compact.json, batches and one sample
    assert runtime.arm.source == compact_arm.source and not runtime.arm.error_frames
    assert np.abs(runtime.position(q) - reference).max() < 1e-9
    assert np.abs(np.array([runtime.position(qi) for qi in q]) - reference).max() < 1e-9
    readouts = tmp_path / "readouts.csv"
    readouts.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\n"
                        + "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.degrees(q))
                        + "\n")
    with contextlib.redirect_stdout(io.StringIO()):
        for params, out in ((folder, "full.csv"), (folder / "compact.json", "compact.csv")):
            assert main(["predict", str(params), str(readouts), "--out", str(tmp_path / out)]) == 0
    values = [np.loadtxt(tmp_path / out, delimiter=",", skiprows=1) for out in ("full.csv",
                                                                                 "compact.csv")]
    assert np.array_equal(values[0], values[1])


def test_the_written_loss_matches_an_independent_one(arm: ap.Arm, small_sim: ap.Simulation,
                                                     with_compliance: ap.Calibration,
                                                     tmp_path: Path) -> None:
    """report.json's and the URDFs' loss = plain Pinocchio of compact.urdf against ap.predict of
    the folder (its calibrated.urdf: the compliance's gravity torques of the calibrated geometry)."""
    folder = ap.write_calibration(with_compliance, arm, tmp_path / "cal", campaign=small_sim.campaign)
    campaign = small_sim.campaign
    logs = [log for log in (campaign.spat, campaign.points, campaign.lengthbar) if log is not None]
    params = with_compliance.parameters
    folder_arm = ap.load_arm(folder / "calibrated.urdf")  # the whole calibration as predict has it
    distances = []
    for log in logs:
        alone = _tool_positions(folder / "compact.urdf", arm, log.q)[0]  # readouts as angles
        full = ap.predict(folder_arm, params, log.q, Samples.of_log(folder_arm, log))
        distances.append(np.linalg.norm(alone - full, axis=1))
    d = np.concatenate(distances) / 1e-6  # um
    entry = json.loads((folder / "report.json").read_text())["urdf_alone_loss_um"]
    assert entry["n_poses"] == d.size == sum(len(log.q) for log in logs)
    assert entry["rms"] == pytest.approx(np.sqrt(np.mean(d**2)), abs=1e-4)
    assert entry["max"] == pytest.approx(d.max(), abs=1e-4) and d.max() > 1.0
    assert "compliance[A2]" in entry["why"] and "encoder maps of A1" in entry["why"]
    for urdf in ("calibrated.urdf", "compact.urdf"):
        top = (folder / urdf).read_text().splitlines()[1]
        found = re.search(r"alone is (\S+) um RMS / (\S+) um max .* the (\d+) poses", top)
        assert found, top
        assert float(found[1]) == pytest.approx(entry["rms"], rel=5e-3)
        assert float(found[2]) == pytest.approx(entry["max"], rel=5e-3)
        assert int(found[3]) == d.size and "compact.json" in top


def test_without_maps_and_extensions_the_urdf_holds_it_all(arm: ap.Arm, small_cal: ap.Calibration,
                                                           tmp_path: Path) -> None:
    """No maps, no extensions: a loss of 0, and the URDFs and the report say it is whole."""
    dh_only = dataclasses.replace(small_cal, parameters=small_cal.parameters.replace(
        encoder_maps={}))
    folder = ap.write_calibration(dh_only, arm, tmp_path / "cal")  # poses: the fitted readouts
    entry = json.loads((folder / "report.json").read_text())["urdf_alone_loss_um"]
    assert entry["rms"] == entry["max"] == 0 and entry["n_poses"] == len(small_cal.q)
    assert "holds the whole calibration" in entry["why"]
    assert "holds the whole calibration" in (folder / "compact.urdf").read_text().splitlines()[1]


def test_identify_prints_the_loss(small_sim: ap.Simulation, tmp_path: Path) -> None:
    """``aacmm-pin identify`` prints the report's URDF-alone loss in one line."""
    ap.write_simulation(small_sim, tmp_path / "camp")
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(["identify", str(tmp_path / "camp"), "--out", str(tmp_path / "cal"),
                     "--model", "proposed"]) in (0, 1)
    entry = json.loads((tmp_path / "cal" / "report.json").read_text())["urdf_alone_loss_um"]
    line = next(t for t in out.getvalue().splitlines() if "URDF alone" in t)
    assert f"{entry['rms']:.3g} um RMS / {entry['max']:.3g} um max" in line
    assert f"over {entry['n_poses']} poses" in line and "compact.json" in line
    assert (tmp_path / "cal" / "compact.urdf").is_file()


def test_a_tree_read_again_gives_its_joints_and_an_edit_reads_afresh(tmp_path: Path) -> None:
    """The joints of a tree read before come back without reading it again; an edit through the
    tree's methods, an edit through its root, or another file name reads afresh (its values,
    its lines, its path in messages)."""
    from aacmm_pin.model.urdf_tree import read_urdf

    tree = read_urdf(ap.load_arm("ur5").source)
    first = tree.joints()
    assert [j.name for j in tree.copy().joints()] == [j.name for j in first]
    assert tree.copy().joints()[0] is first[0]  # remembered: same text, lines, path
    with pytest.raises(ValueError):
        first[0].origin[0, 3] = 1.0  # shared between reads: read-only
    edited = tree.copy()
    name = next(j.name for j in first if j.type == "revolute")
    edited.make_fixed(name)
    assert {j.name: j.type for j in edited.joints()}[name] == "fixed"
    by_root = tree.copy()
    by_root.root.find(f"joint[@name='{name}']").set("type", "prismatic")
    assert {j.name: j.type for j in by_root.joints()}[name] == "prismatic"
    assert {j.name: j.type for j in tree.joints()}[name] == "revolute"
    broken = tree.copy()
    broken.root.find(f"joint[@name='{name}']/origin").set("xyz", "0 0 nan")
    broken.path = tmp_path / "elsewhere.urdf"
    with pytest.raises(ap.AacmmError, match="elsewhere.urdf.*finite numbers"):
        broken.joints()
