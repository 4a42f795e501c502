r"""Write URDFs of serial robots given by classic DH tables, in aacmm_pin's URDF conventions.

Run once; the URDFs are committed: ``python urdf/make_serial_dh.py`` writes ``ur5.urdf`` and
``wam7.urdf`` next to this script (``python urdf/make_serial_dh.py ur5`` writes one of them).

**The chain.** Joint i of a classic (distal, Denavit-Hartenberg 1955 / Spong) DH table is

    (i-1)T(i) = Rz(theta_i + offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i)

with theta_i the joint readout. In the URDF every elementary transform is its own joint, applied
root to tip (names as written; ``<i>`` is the joint number 1..n):

===============  ========  =============================================================================
joint            kind      transform
===============  ========  =============================================================================
``theta<i>``     nominal   Rz(offset_i), only where offset_i != 0
``dth<i>``       error     rotation about axis i (``dth`` = rotation about the *next* revolute's axis)
``A<i>``         axis      revolute about z, the readout theta_i; its child link ``link<i>`` is body i
``L<i>z``        nominal   Tz(d_i), only where d_i != 0
``dz<i>``        error     translation along z
``L<i>x``        nominal   Tx(a_i), only where a_i != 0
``dx<i>``        error     translation along x
``alpha<i>``     nominal   Rx(alpha_i), only where alpha_i != 0
``a<i>``         error     rotation about x
``b<i>``         error     rotation about y, only where axis i+1 is parallel to axis i (alpha_i = 0,
                           i < n): Hayati's parameter, without which a small tilt between parallel
                           axes cannot be represented (UR5: b2, b3 for the parallel axes 2-3-4)
===============  ========  =============================================================================

then the fixed joint ``tool`` (child link ``stylus``) holds the tool vector in DH frame n. All error
frames are zero here, so the nominal model is exactly the published table. Error frame names follow
``aacmm_pin.model.arm.ERROR_FRAME_PATTERN`` (``dth|dx|dy|dz|a|b|c`` + digits); the nominal joints
(``theta<i>``, ``L<i>z``, ``L<i>x``, ``alpha<i>``) do not match it, the axes are ``A<i>`` (upper case:
the error frame ``a<i>`` differs from the axis ``A<i>`` only in case).

**What a calibration can see.** Some error frames are redundant by construction, and the
identification's gauge rules (truncated SVD, ``Calibration.unidentifiable``) hold them: every error
frame of the last joint (``dth<n> dz<n> dx<n> a<n>``) with the tool vector (a point tool; a rigid
transform after the last axis only moves the tool point), ``dth1`` with the base rotation about z
(``gamma0``), and along a run of parallel axes the translations along those axes (UR5: only
``dz2 + dz3 + dz4`` acts). They are kept so that every DH parameter of the table has its error frame.

**Mass properties** (for Pinocchio's gravity, e.g. a joint compliance model). Each link's mass,
centre of mass and inertia (about the centre of mass) are given in DH frame i, as makers publish
them; the URDF puts them on ``link<i>`` (the frame right after the revolute), moved through the
nominal Tz(d_i) Tx(a_i) Rx(alpha_i). Sources are given per robot below; where a maker publishes no
inertia tensor, solid cylinders of the link's size stand in (stated where used).

**Visuals.** Primitive cylinders only: a joint housing on each axis (axis 1 on the base link, axis
i+1 on ``link<i>``) and one cylinder along each nonzero d_i and a_i, plus the stylus sphere (a
1.5 in SMR, radius 19.05 mm).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HALF_PI = math.pi / 2
_ZERO = 1e-12


@dataclass(frozen=True)
class DHJoint:
    """One row of a classic DH table and the mass properties of the link it moves (SI units)."""

    d: float
    """Offset along the previous z (m)."""
    a: float
    """Length along the new x (m)."""
    alpha: float
    """Twist about the new x (rad)."""
    offset: float = 0.0
    """Constant added to the readout: theta_i = readout + offset (rad)."""
    limits_deg: tuple[float, float] = (-180.0, 180.0)
    """Lower and upper joint limit (deg)."""
    mass: float = 1.0
    """Link mass (kg)."""
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Centre of mass in DH frame i (m)."""
    inertia: tuple[float, float, float, float, float, float] = (1e-3, 1e-3, 1e-3, 0.0, 0.0, 0.0)
    """Inertia about the centre of mass, axes of DH frame i: ixx, iyy, izz, ixy, ixz, iyz (kg m^2)."""
    radius: float = 0.04
    """Radius of the visual cylinders (m)."""
    effort: float = 0.0
    """Torque limit written to the URDF (N m; 0 where the maker's value is not used here)."""
    velocity: float = 3.14
    """Speed limit written to the URDF (rad/s)."""


@dataclass(frozen=True)
class SerialArm:
    """A serial robot: its DH table, tool vector, base body and where the data came from."""

    name: str
    """Robot name (URDF ``robot name``, output file ``<name>.urdf``)."""
    joints: tuple[DHJoint, ...]
    """DH rows, joint 1 first."""
    tool: tuple[float, float, float]
    """Tool vector (stylus / SMR centre) in DH frame n (m)."""
    source: str
    """Where the table and mass properties come from (written into the URDF as a comment)."""
    base_mass: float = 1.0
    """Mass of the base link (kg; irrelevant to a fixed base's dynamics, kept for viewers)."""
    base_radius: float = 0.06
    """Radius of the base cylinder (m)."""
    base_height: float = 0.05
    """Height of the base cylinder, which ends at DH frame 0 (m); a housing on axis 1 sits on it."""
    colour: tuple[float, float, float, float] = (0.6, 0.6, 0.65, 1.0)
    """RGBA of the links."""
    extra_comments: tuple[str, ...] = field(default_factory=tuple)
    """Further lines for the URDF's header comment."""
    sizes: dict[str, object] = field(default_factory=dict)
    """Plausible sizes of its errors, SI, with their ``source`` (``<name>.sizes.json`` beside the
    URDF, read by ``aacmm_pin.model.sizes``); empty: no sizes file (the default AACMM's sizes)."""


def cylinder_inertia(mass: float, radius: float, length: float, axis: str
                     ) -> tuple[float, float, float, float, float, float]:
    """Return (ixx, iyy, izz, 0, 0, 0) of a solid cylinder about its centre, axis along x, y or z."""
    i_axis = 0.5 * mass * radius * radius
    i_perp = mass * (3 * radius * radius + length * length) / 12
    diag = [i_perp, i_perp, i_perp]
    diag["xyz".index(axis)] = i_axis
    return (diag[0], diag[1], diag[2], 0.0, 0.0, 0.0)


def _deg(lower_rad: float, upper_rad: float) -> tuple[float, float]:
    """Return joint limits given in rad as (lower, upper) in deg."""
    return math.degrees(lower_rad), math.degrees(upper_rad)


# --------------------------------------------------------------------------------------- UR5
# DH table: Universal Robots, "Parameters for calculations of kinematics and dynamics" (support
# article 45257) and the CB3 user manual, Table "DH parameters for the UR5 serie 3" (CB3):
# d1 0.089159, a2 -0.425, a3 -0.39225, d4 0.10915, d5 0.09465, d6 0.0823 m,
# alpha pi/2, 0, 0, pi/2, -pi/2, 0; theta offsets 0 (ros-industrial/universal_robot
# ur_description/config/ur5/physical_parameters.yaml has the same numbers).
# Masses: ur_description physical_parameters.yaml (3.7, 8.393, 2.275, 1.219, 1.219, 0.1879 kg; base
# 4.0 kg, "might be incorrect" there). Centres of mass in DH frame i: UR's support article (UR5
# rows: [0, -0.02561, 0.00193], [0.2125, 0, 0.11336], [0.15, 0, 0.0265], [0, -0.0018, 0.01634],
# [0, 0.0018, 0.01634], [0, 0, -0.001159] m). UR publishes no inertia tensors for the UR5:
# PLAUSIBLE VALUES, solid cylinders with ur_description's link radii and lengths, the cylinder
# along the link (axis 1 is y1, the upper arm x2, the forearm x3, axis 4 is y4, axis 5 is y5,
# axis 6 is z6).
# Limits: +-360 deg on every joint; 150 N m (joints 1-3), 28 N m (4-6), 3.15 rad/s (ur_description).
# Tool: the data set's SMR (jacobi2025-laser-tracker): 31 mm along z6. That data set's commanded
# positions follow d5 = 0.09456 m, not UR's 0.09465 m (a digit swap?): this model gives them to
# 0.093 mm, and to 0.003 mm over all 1020 rows with dz5 = -0.00009 m.
UR5 = SerialArm(
    name="ur5",
    joints=(
        DHJoint(d=0.089159, a=0.0, alpha=HALF_PI, limits_deg=(-360, 360), mass=3.7,
                com=(0.0, -0.02561, 0.00193), inertia=cylinder_inertia(3.7, 0.075, 0.178, "y"),
                radius=0.06, effort=150.0, velocity=3.15),
        DHJoint(d=0.0, a=-0.425, alpha=0.0, limits_deg=(-360, 360), mass=8.393,
                com=(0.2125, 0.0, 0.11336), inertia=cylinder_inertia(8.393, 0.06, 0.425, "x"),
                radius=0.054, effort=150.0, velocity=3.15),
        DHJoint(d=0.0, a=-0.39225, alpha=0.0, limits_deg=(-360, 360), mass=2.275,
                com=(0.15, 0.0, 0.0265), inertia=cylinder_inertia(2.275, 0.06, 0.39225, "x"),
                radius=0.04, effort=150.0, velocity=3.15),
        DHJoint(d=0.10915, a=0.0, alpha=HALF_PI, limits_deg=(-360, 360), mass=1.219,
                com=(0.0, -0.0018, 0.01634), inertia=cylinder_inertia(1.219, 0.06, 0.12, "y"),
                radius=0.045, effort=28.0, velocity=3.15),
        DHJoint(d=0.09465, a=0.0, alpha=-HALF_PI, limits_deg=(-360, 360), mass=1.219,
                com=(0.0, 0.0018, 0.01634), inertia=cylinder_inertia(1.219, 0.06, 0.12, "y"),
                radius=0.045, effort=28.0, velocity=3.15),
        DHJoint(d=0.0823, a=0.0, alpha=0.0, limits_deg=(-360, 360), mass=0.1879,
                com=(0.0, 0.0, -0.001159), inertia=cylinder_inertia(0.1879, 0.0375, 0.0345, "z"),
                radius=0.0375, effort=28.0, velocity=3.15),
    ),
    tool=(0.0, 0.0, 0.031),
    source="Universal Robots UR5 (CB3), classic DH table of UR's support article 45257 / CB3 manual "
           "(UR5 serie 3); masses and centres of mass from UR, inertia tensors approximated",
    base_mass=4.0,
    base_radius=0.075,
    base_height=0.02,  # a mounting plate below DH frame 0 (the base's mounting face)
    colour=(0.62, 0.66, 0.72, 1.0),
    extra_comments=("Tool: SMR centre 31 mm along z6 (laser-tracker data set jacobi2025, whose commanded "
                    "positions use d5 = 0.09456 m: dz5 = -0.00009 m reproduces them).",),
    sizes={
        "source": (
            "Physics and makers' figures, not fitted to any data. Cast and machined aluminium "
            "links on the nominal DH table (not UR's per-robot factory calibration): DH angle "
            "errors of about 0.06 deg (1e-3 rad) and lengths of about 0.5 mm; the SMR adapter is "
            "not a calibrated tool (1 mm). Harmonic drive joints: transmission error and lost "
            "motion of about 1 arcmin peak to peak, so about 30 arcsec (1.5e-4 rad) for a map "
            "node, an encoder harmonic and backlash, 20 arcsec (1e-4 rad) for crosstalk; "
            "torsional stiffness of the drives and bearings of order 3e4 N m/rad, compliance "
            "3e-5 rad/(N m) (3x the AACMM's: about 0.1 deg under the shoulder's 50 N m of "
            "gravity torque). Instrument frame: the default sizes."),
        "dh_angle": 1e-3, "dh_length": 5e-4, "tool": 1e-3, "map_node": 1.5e-4,
        "effects": {"compliance": 3e-5, "backlash": 1.5e-4, "crosstalk": 1e-4, "encoder": 1.5e-4},
    },
)

# --------------------------------------------------------------------------------------- WAM
# DH table: Barrett Technology, WAM Arm User's Manual D1001 (version AH.00, 2008), Table 5
# "7-DOF WAM frame parameters": a = 0, 0, 0.045, -0.045, 0, 0, 0; d = 0, 0, 0.55, 0, 0.3, 0, 0.06 m;
# alpha = -pi/2, pi/2, -pi/2, pi/2, -pi/2, pi/2, 0; theta offsets 0 (Spong's classic DH). libbarrett's
# config/wam7w.conf has the same table up to d7 = 0.0609 and a last twist of -pi/2 undone by its
# toolplate (+pi/2); the laser-tracker data set is reproduced with the manual's d7 = 0.06.
# Limits: manual Table 6 (rad): +-2.6, +-2.0, +-2.8, -0.9..3.1, -4.76..1.24, +-1.6, +-3.0.
# Masses, centres of mass and full inertia tensors (about the centre of mass, DH frame i): Barrett's
# inertial specifications (Sept 2008) as shipped in libbarrett config/wam7w.conf (7-DOF WAM with
# the wrist). Base 9.97 kg (Barrett's base-link value used in public WAM models).
# Tool: the data set's SMR: 44 mm along z7 beyond d7 (least squares on the data set's commanded
# positions: (0.00001, 0.00003, 44.0001) mm; with (0, 0, 44) mm they are reproduced to 0.003 mm).
WAM7 = SerialArm(
    name="wam7",
    joints=(
        DHJoint(d=0.0, a=0.0, alpha=-HALF_PI, limits_deg=_deg(-2.6, 2.6), mass=10.7677,
                com=(-4.43e-3, 121.89e-3, -0.66e-3),
                inertia=(0.13488033, 0.11328369, 0.0904633, -0.00213041, -0.00012485, 0.00068555),
                radius=0.09),
        DHJoint(d=0.0, a=0.0, alpha=HALF_PI, limits_deg=_deg(-2.0, 2.0), mass=3.8749,
                com=(-2.37e-3, 31.06e-3, 15.42e-3),
                inertia=(0.02140958, 0.01377875, 0.01558906, 0.00027172, 0.00002461, -0.0018192),
                radius=0.07),
        DHJoint(d=0.55, a=0.045, alpha=-HALF_PI, limits_deg=_deg(-2.8, 2.8), mass=1.8023,
                com=(-38.26e-3, 207.51e-3, 0.03e-3),
                inertia=(0.05911077, 0.0032455, 0.05927043, -0.00249612, 0.00000738, -0.00001767),
                radius=0.045),
        DHJoint(d=0.0, a=-0.045, alpha=HALF_PI, limits_deg=_deg(-0.9, 3.1), mass=2.17266212,
                com=(0.00553408, 0.00006822, 0.11927695),
                inertia=(0.01067491, 0.01058659, 0.00282036, 0.00004503, -0.00135557, -0.00011002),
                radius=0.045),
        DHJoint(d=0.3, a=0.0, alpha=-HALF_PI, limits_deg=_deg(-4.76, 1.24), mass=0.35655692,
                com=(0.00005483, 0.02886286, 0.00148493),
                inertia=(0.00037112, 0.00019434, 0.00038209, -0.00000008, -0.00000003, -0.00001613),
                radius=0.04),
        DHJoint(d=0.0, a=0.0, alpha=HALF_PI, limits_deg=_deg(-1.6, 1.6), mass=0.40915886,
                com=(-0.00005923, -0.01686123, 0.02419052),
                inertia=(0.00054889, 0.00023846, 0.00045133, 0.00000019, -0.0000001, -0.0000443),
                radius=0.035),
        DHJoint(d=0.06, a=0.0, alpha=0.0, limits_deg=_deg(-3.0, 3.0), mass=0.0754827,
                com=(0.00014836, 0.00007252, -0.00335185),
                inertia=(0.00003911, 0.00003877, 0.00007614, 0.00000019, 0.0, 0.0),
                radius=0.03),
    ),
    tool=(0.0, 0.0, 0.044),
    source="Barrett WAM 7-DOF, classic DH table of the WAM Arm User's Manual D1001 (Table 5); "
           "mass properties from Barrett's inertial specifications (libbarrett wam7w.conf)",
    base_mass=9.97059584,
    base_radius=0.09,
    base_height=0.346,
    colour=(0.78, 0.78, 0.8, 1.0),
    extra_comments=("Tool: SMR centre 44 mm along z7 beyond d7 (laser-tracker data set jacobi2025).",),
    sizes={
        "source": (
            "Physics and makers' figures, not fitted to any data. A cable-driven arm: joint "
            "zeros are set by homing against hand-positioned references and the links are "
            "assembled aluminium tubes, so DH angle errors of about 0.1 deg (1.75e-3 rad) and "
            "lengths of about 1 mm; the SMR adapter on the wrist is not a calibrated tool (2 mm). "
            "The encoders sit on the motors before the cable transmissions (ratios of about 10 to 42) and "
            "differentials (J2/J3, J5/J6), so capstan and pulley runout, cable slack and "
            "friction hysteresis show as angle errors that follow the joint angle, the direction "
            "of motion and the coupled joint, of about 0.06 deg (1e-3 rad) each; cable "
            "stretch makes the joints compliant: stiffness of order 3e3 N m/rad, compliance "
            "3e-4 rad/(N m) (10x a UR5's harmonic drives), i.e. about 0.5 deg under the "
            "shoulder's 30 N m of gravity torque. Instrument frame: the default sizes."),
        "dh_angle": 1.75e-3, "dh_length": 1e-3, "tool": 2e-3, "map_node": 1e-3,
        "effects": {"compliance": 3e-4, "backlash": 1e-3, "crosstalk": 1e-3, "encoder": 1e-3},
    },
)

ROBOTS = {arm.name: arm for arm in (UR5, WAM7)}


# --------------------------------------------------------------------------------------- chain
def chain(arm: SerialArm) -> list[tuple[str, str, str, float]]:
    """Return the joints root first as (name, kind, elementary transform, value).

    ``kind`` is ``revolute``, ``nominal`` or ``error``; the elementary transform is ``x``/``y``/``z``
    (translation) or ``a``/``b``/``c`` (rotation about x/y/z); value in m or rad.
    """
    out: list[tuple[str, str, str, float]] = []
    n = len(arm.joints)
    for i, row in enumerate(arm.joints, start=1):
        if abs(row.offset) > _ZERO:
            out.append((f"theta{i}", "nominal", "c", row.offset))
        out.append((f"dth{i}", "error", "c", 0.0))
        out.append((f"A{i}", "revolute", "c", 0.0))
        if abs(row.d) > _ZERO:
            out.append((f"L{i}z", "nominal", "z", row.d))
        out.append((f"dz{i}", "error", "z", 0.0))
        if abs(row.a) > _ZERO:
            out.append((f"L{i}x", "nominal", "x", row.a))
        out.append((f"dx{i}", "error", "x", 0.0))
        if abs(row.alpha) > _ZERO:
            out.append((f"alpha{i}", "nominal", "a", row.alpha))
        out.append((f"a{i}", "error", "a", 0.0))
        if i < n and abs(math.sin(row.alpha)) < _ZERO:
            out.append((f"b{i}", "error", "b", 0.0))
    return out


# --------------------------------------------------------------------------------------- URDF text
def _fmt(v: float) -> str:
    return "0" if abs(v) < 1e-15 else f"{v:.12g}"


def _vec(values) -> str:
    return " ".join(_fmt(float(v)) for v in values)


def _rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _cylinder(length: float, radius: float, xyz, rpy) -> str:
    return ("    <visual>\n"
            f'      <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
            f'      <geometry><cylinder length="{_fmt(length)}" radius="{_fmt(radius)}"/></geometry>\n'
            '      <material name="body"/>\n'
            "    </visual>\n")


def _inertial(mass: float, xyz, rpy, inertia) -> str:
    ixx, iyy, izz, ixy, ixz, iyz = inertia
    return ("    <inertial>\n"
            f'      <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
            f'      <mass value="{_fmt(mass)}"/>\n'
            f'      <inertia ixx="{_fmt(ixx)}" ixy="{_fmt(ixy)}" ixz="{_fmt(ixz)}" iyy="{_fmt(iyy)}" '
            f'iyz="{_fmt(iyz)}" izz="{_fmt(izz)}"/>\n'
            "    </inertial>\n")


def _body_link(name: str, row: DHJoint) -> str:
    """Link ``link<i>``: origin on axis i, z along it; mass properties moved from DH frame i."""
    frame_i = np.array([row.a, 0.0, row.d])  # DH frame i in link<i>: Tz(d) Tx(a) Rx(alpha)
    com = frame_i + _rot_x(row.alpha) @ np.asarray(row.com, dtype=float)
    parts = [f'  <link name="{name}">\n', _inertial(row.mass, com, (row.alpha, 0, 0), row.inertia)]
    r = row.radius
    parts.append(_cylinder(2.4 * r, r, frame_i, (row.alpha, 0, 0)))  # housing on axis i+1 (z_i)
    if abs(row.d) > 1e-9:
        parts.append(_cylinder(abs(row.d), 0.7 * r, (0, 0, row.d / 2), (0, 0, 0)))
    if abs(row.a) > 1e-9:
        parts.append(_cylinder(abs(row.a), 0.7 * r, (row.a / 2, 0, row.d), (0, HALF_PI, 0)))
    parts.append("  </link>\n")
    return "".join(parts)


def make_urdf(arm: SerialArm) -> str:
    """Return the URDF text of a serial arm in aacmm_pin's conventions."""
    steps = chain(arm)
    n_err = sum(kind == "error" for _, kind, _, _ in steps)
    head = [
        '<?xml version="1.0"?>\n',
        f"<!-- {arm.name}: {arm.source}. -->\n",
        f"<!-- Written by urdf/make_serial_dh.py ({len(arm.joints)} axes A1..A{len(arm.joints)}, "
        f"{n_err} error frames at 0, classic DH: Rz(theta) Tz(d) Tx(a) Rx(alpha)). -->\n",
        *[f"<!-- {line} -->\n" for line in arm.extra_comments],
        f'<robot name="{arm.name}">\n',
        f'  <material name="body"><color rgba="{_vec(arm.colour)}"/></material>\n',
        '  <material name="smr"><color rgba="0.85 0.85 0.9 1"/></material>\n',
        '  <link name="base_link">\n',
        _inertial(arm.base_mass, (0, 0, -arm.base_height / 2), (0, 0, 0),
                  cylinder_inertia(arm.base_mass, arm.base_radius, arm.base_height, "z")),
        _cylinder(arm.base_height, arm.base_radius, (0, 0, -arm.base_height / 2), (0, 0, 0)),
        _cylinder(2.4 * arm.joints[0].radius, arm.joints[0].radius,
                  (0, 0, 1.2 * arm.joints[0].radius), (0, 0, 0)),  # housing on axis 1
        "  </link>\n",
    ]
    parts = head
    parent = "base_link"
    axis = 0
    for name, kind, elem, value in steps:
        xyz, rpy = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        if elem in "xyz":
            xyz["xyz".index(elem)] = value
        else:
            rpy["abc".index(elem)] = value
        if kind == "revolute":
            axis += 1
            row = arm.joints[axis - 1]
            child = f"link{axis}"
            lo, hi = (math.radians(v) for v in row.limits_deg)
            parts.append(f'  <joint name="{name}" type="revolute">\n'
                         f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
                         f'    <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
                         '    <axis xyz="0 0 1"/>\n'
                         f'    <limit lower="{_fmt(lo)}" upper="{_fmt(hi)}" effort="{_fmt(row.effort)}" '
                         f'velocity="{_fmt(row.velocity)}"/>\n'
                         "  </joint>\n")
            parts.append(_body_link(child, row))
        else:
            child = f"{name}_frame"
            parts.append(f'  <joint name="{name}" type="fixed">\n'
                         f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
                         f'    <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
                         "  </joint>\n")
            parts.append(f'  <link name="{child}"/>\n')
        parent = child
    parts.append('  <joint name="tool" type="fixed">\n'
                 f'    <parent link="{parent}"/>\n    <child link="stylus"/>\n'
                 f'    <origin xyz="{_vec(arm.tool)}" rpy="0 0 0"/>\n  </joint>\n'
                 '  <link name="stylus">\n    <visual>\n      <origin xyz="0 0 0" rpy="0 0 0"/>\n'
                 '      <geometry><sphere radius="0.01905"/></geometry>\n'
                 '      <material name="smr"/>\n    </visual>\n  </link>\n')
    parts.append("</robot>\n")
    return "".join(parts)


def main(argv: list[str]) -> None:
    """Write ``<name>.urdf`` next to this script for the robots named (default: all)."""
    names = argv or list(ROBOTS)
    unknown = [n for n in names if n not in ROBOTS]
    if unknown:
        raise SystemExit(f"unknown robot(s) {', '.join(unknown)}; choose from {', '.join(ROBOTS)}")
    for name in names:
        out = Path(__file__).with_name(f"{name}.urdf")
        out.write_text(make_urdf(ROBOTS[name]))
        print(f"wrote {out}")
        if ROBOTS[name].sizes:
            sizes = out.with_name(f"{name}.sizes.json")
            sizes.write_text(json.dumps({"units": "SI", **ROBOTS[name].sizes}, indent=2) + "\n")
            print(f"wrote {sizes}")


if __name__ == "__main__":
    main(sys.argv[1:])
