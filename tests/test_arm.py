"""The arm: URDF conventions (axes, error frames, tool), a user's own arm, bad URDFs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from aacmm_pin.effects import calibrated as kinematics
from aacmm_pin.errors import ArmModelError, FrameNotFound
from aacmm_pin.model.arm import load_arm
from aacmm_pin.model.parameters import Parameters
from tests.helpers import DH_NAMES, ENV, d_a, d_b, d_c, d_x, d_z

TWO_AXIS = """<?xml version="1.0"?>
<robot name="two_axis">
  <link name="base"/><link name="l1"/><link name="f1"/><link name="f2"/><link name="f3"/>
  <link name="l2"/><link name="tip"/>
  <joint name="J1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="0" velocity="1"/></joint>
  <joint name="H" type="fixed"><parent link="l1"/><child link="f1"/>
    <origin xyz="0 0 0.3"/></joint>
  <joint name="dx21" type="fixed"><parent link="f1"/><child link="f2"/>
    <origin xyz="{dx} 0 0"/></joint>
  <joint name="a21" type="fixed"><parent link="f2"/><child link="f3"/>
    <origin rpy="{a} 0 0"/></joint>
  <joint name="J2" type="revolute"><parent link="f3"/><child link="l2"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="0" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/>
    <origin xyz="0.5 0 0"/></joint>
</robot>
"""


def test_default_arm_conventions(arm):
    """The embedded arm has axes A1..A7, the paper's 22 error frames in order, tool (0,0,-120) mm."""
    assert arm.axis_names == [f"A{n}" for n in range(1, 8)]
    assert arm.error_names == DH_NAMES
    np.testing.assert_allclose(arm.nominal_tool, [0, 0, -0.12])
    assert all(v == 0.0 for v in arm.nominal_errors.values())
    np.testing.assert_allclose(np.degrees(arm.joint_limits[:, 1]), [180, 100, 180, 150, 180, 120, 180])


def test_default_arm_has_plausible_inertias_and_primitive_visuals(arm):
    """A few kg in all, positive masses, and only cylinders/spheres for MeshCat."""
    model = arm.runtime_model()
    total = sum(inertia.mass for inertia in model.inertias)
    assert 2.0 < total < 6.0
    urdf = yourdfpy.URDF.load(str(arm.source), build_scene_graph=False, load_meshes=False)
    shapes = {type(v.geometry.cylinder or v.geometry.sphere).__name__
              for link in urdf.robot.links for v in link.visuals}
    assert shapes <= {"Cylinder", "Sphere"} and "Cylinder" in shapes


def test_identification_model_has_one_joint_per_parameter(arm):
    """Identification model: 6 base + 7 axes + 22 error frames + 3 tool joints, all 1-DOF."""
    ident = arm.identification
    assert ident.model.nq == ident.model.nv == 38
    assert len(set(ident.error_idx) | set(ident.axis_idx) | set(ident.tool_idx)
               | set(ident.base_idx)) == 38


def test_user_arm_with_two_axes(tmp_path):
    """Any URDF following the conventions works: here two axes, two error frames."""
    dx, a = 0.001, 0.01
    path = tmp_path / "two.urdf"
    path.write_text(TWO_AXIS.format(dx=dx, a=a))
    arm = load_arm(path)
    assert arm.axis_names == ["J1", "J2"] and arm.error_names == ["dx21", "a21"]
    np.testing.assert_allclose(list(arm.nominal_errors.values()), [dx, a], atol=1e-15)
    q = np.array([[0.3, -0.4]])
    ref = (d_c(0.3) @ d_z(0.3) @ d_x(dx) @ d_a(a) @ d_b(-0.4) @ np.array([0.5, 0, 0, 1]))[:3]
    params = Parameters.nominal(arm)
    np.testing.assert_allclose(kinematics.stylus_positions(arm, params, q)[0], ref, atol=1e-15)
    np.testing.assert_allclose(kinematics.predict(arm, params, q)[0], ref, atol=1e-15)


def test_urdf_string_writes_values_that_load_back(arm, tmp_path):
    """Error frame values written into the URDF are read back as the nominal values."""
    values = {name: 1e-4 * (k + 1) for k, name in enumerate(arm.error_names)}
    path = tmp_path / "cal.urdf"
    path.write_text(arm.urdf_string(values, np.array([0.001, 0.002, -0.121])))
    again = load_arm(path)
    np.testing.assert_allclose([again.nominal_errors[n] for n in values], list(values.values()),
                               atol=1e-12)
    np.testing.assert_allclose(again.nominal_tool, [0.001, 0.002, -0.121], atol=1e-15)
    model = pin.buildModelFromUrdf(str(path))
    assert model.nq == 7


EXTRAS = """
  <!-- the integrator's note -->
  <gazebo reference="base_link"><material>Gazebo/Grey</material></gazebo>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="A1"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>50</mechanicalReduction></actuator></transmission>
  <ros2_control name="arm" type="system"><hardware><plugin>mock_components/GenericSystem</plugin>
    </hardware></ros2_control>
</robot>"""


def test_calibrated_urdf_keeps_everything_else_the_user_wrote(arm, tmp_path):
    """Writing calibrated values changes the error frames' and the tool's origins only: comments,
    <gazebo>, <transmission>, <ros2_control>, visuals and inertias stay as written, and an
    independent reader (yourdfpy) reads the values back."""
    path = tmp_path / "mine.urdf"
    path.write_text(arm.source.read_text().replace("</robot>", EXTRAS))
    mine = load_arm(path)
    values = {name: 1e-4 * (k + 1) for k, name in enumerate(mine.error_names)}
    text = mine.urdf_string(values, np.array([0.001, 0.002, -0.121]))
    for kept in ("the integrator's note", "Gazebo/Grey", "<mechanicalReduction>50<",
                 "mock_components/GenericSystem", "<inertia ", "<cylinder "):
        assert kept in text, kept
    assert text.count("<joint ") == arm.source.read_text().count("<joint ") + 1  # + transmission's
    out = tmp_path / "calibrated.urdf"
    out.write_text(text)
    robot = yourdfpy.URDF.load(str(out), build_scene_graph=False, load_meshes=False).robot
    origins = {j.name: np.asarray(j.origin, float) for j in robot.joints}
    for name, value in values.items():
        np.testing.assert_allclose(origins[name], mine.error_frame(name).transform(value),
                                   atol=1e-15)
    np.testing.assert_allclose(origins["tool"][:3, 3], [0.001, 0.002, -0.121], atol=1e-15)
    assert mine.urdf_robot(values).name == "aacmm7"  # the yourdfpy view of the same text


def test_loading_an_arm_does_not_import_yourdfpy():
    """The arm is read as an XML tree: neither yourdfpy nor trimesh (~0.3 s of imports) is loaded
    to load an arm, build its models or write its URDF."""
    code = ("import sys\nfrom aacmm_pin import load_arm\narm = load_arm()\n"
            "arm.identification; arm.runtime_model(); arm.urdf_string()\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'yourdfpy', 'trimesh'}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV,
                         check=True, timeout=120).stdout
    assert out.strip() == "[]"


def test_unknown_parameter_name_lists_choices(arm):
    """Setting a parameter the arm lacks names it and lists the valid ones."""
    with pytest.raises(FrameNotFound, match="dx99.*dx21"):
        arm.urdf_string({"dx99": 0.0})


@pytest.mark.parametrize("edit, message", [
    (lambda s: s.replace('name="tool"', 'name="probe"'),
     "no fixed joint 'tool' .*and no link 'tool0'.*--tool-frame LINK"),
    (lambda s: s.replace('<origin xyz="{dx} 0 0"/>', '<origin xyz="0 {dx} 0"/>'),
     "must hold a pure translation along"),
    (lambda s: s.replace('<origin rpy="{a} 0 0"/>', '<origin rpy="0 {a} 0"/>'),
     "must hold a pure rotation about"),
    (lambda s: s.replace("</robot>", "<robot>"), "line"),
    (lambda s: s.replace('<origin xyz="0 0 0.3"/>', '<origin xyz="0 0 0,3"/>'),
     r"line 7: joint 'H': origin xyz: 3 finite numbers expected, got '0 0 0,3'"),
    (lambda s: s.replace('<origin xyz="0 0 0.3"/>', '<origin xyz="0 0 nan"/>'),
     "line 7: joint 'H': origin xyz"),
    (lambda s: s.replace('<origin xyz="0 0 0.3"/>', '<origin xyz="0 0 0_3"/>'),
     "line 7: joint 'H': origin xyz"),  # Python reads 0_3 as 3, URDF parsers refuse it
    (lambda s: s.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
     "joint 'J2': axis xyz is zero"),
    (lambda s: s.replace('type="revolute"><parent link="base"/>', 'type="hinge"><parent link="base"/>'),
     "line 5: joint 'J1': type 'hinge'"),
    (lambda s: s.replace('<child link="tip"/>', '<child link="tipp"/>'),
     "joint 'tool': child link 'tipp' is not declared"),
    (lambda s: s.replace('<parent link="l2"/><child link="tip"/>', '<child link="tip"/>'),
     "joint 'tool': no <parent link"),
    (lambda s: s.replace('name="H"', 'name="J1"'), "line 7: joint 'J1': a second joint"),
    (lambda s: s.replace('<robot name="two_axis">', '<robt name="two_axis">').replace(
        "</robot>", "</robt>"), "root element is <robt>"),
])
def test_bad_urdf_is_named(tmp_path, edit, message):
    """A URDF that breaks a convention or XML syntax raises ArmModelError naming file and cause."""
    path = tmp_path / "bad.urdf"
    path.write_text(edit(TWO_AXIS).format(dx=0.001, a=0.01))
    with pytest.raises(ArmModelError, match=message) as info:
        load_arm(path)
    assert "bad.urdf" in str(info.value)


def test_missing_arm_names_embedded_choices():
    """An arm that is neither a file nor an embedded name says so."""
    with pytest.raises(ArmModelError, match="embedded: aacmm7, ur5, wam7"):
        load_arm("no_such_arm")
