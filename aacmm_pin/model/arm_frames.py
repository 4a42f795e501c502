"""The URDF's joints read as an arm's parts: tool chains, error frames, and Pinocchio's model.

The conventions are :mod:`aacmm_pin.model.arm`'s: a fixed joint ``tool`` (or ``tool_<name>``)
carries each tool, a fixed joint named as :data:`ERROR_FRAME_PATTERN` holds one elementary
transform of the paper's Eq. (2) (:class:`ErrorFrame`), revolute and continuous joints are the
axes. :class:`~aacmm_pin.model.arm.Arm` is built from these pieces.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from aacmm_pin.data.couplings import Coupling
from aacmm_pin.errors import ArmModelError
from aacmm_pin.model.urdf_tree import Joint, UrdfTree

ERROR_FRAME_PATTERN = re.compile(r"^(dth|dx|dy|dz|a|b|c)(\d+)$")
"""Names of the error frames' fixed joints: the kind of transform, then the parameter's digits."""
TOOL_JOINT = "tool"
"""Name of the single tool joint."""
TOOL_PATTERN = re.compile(r"^tool(?:_([A-Za-z0-9][A-Za-z0-9_]*))?$")
"""Names of the tool joints: ``tool`` or ``tool_<name>``."""
MOVABLE = ("revolute", "continuous")
"""The URDF joint types of an axis."""
_UNIT = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}
_ROT_LETTER = {"a": "x", "b": "y", "c": "z"}
_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class ErrorFrame:
    """One DH error parameter: a fixed joint holding one elementary transform."""

    name: str
    """Joint name, the paper's parameter name (e.g. ``dx21``, ``a21``, ``dth30``)."""
    is_angle: bool
    """True for a rotation (value in rad), False for a translation (value in m)."""
    axis: np.ndarray
    """Unit direction of the translation or rotation axis in the parent frame, shape (3,)."""
    nominal: float
    """The value the URDF holds (m or rad)."""

    def transform(self, value: float) -> np.ndarray:
        """Return the joint origin for this value, a 4x4 homogeneous transform."""
        out = np.eye(4)
        if self.is_angle:
            out[:3, :3] = pin.exp3(self.axis * value)
        else:
            out[:3, 3] = self.axis * value
        return out


def tool_chains(joints: list[Joint], path: Path | str) -> dict[str, list[Joint]]:
    """Return tool joint name -> the joints from the root link to that tool joint, root first."""
    by_child = {j.child: j for j in joints}
    tools = [j for j in joints if j.type == "fixed" and TOOL_PATTERN.match(j.name)]
    if not tools:
        raise ArmModelError(path, f"no fixed joint named '{TOOL_JOINT}' (or 'tool_<name>') carrying "
                                  f"the stylus (joints: {', '.join(j.name for j in joints)})")
    if len(tools) > 1 and any(j.name == TOOL_JOINT for j in tools):
        raise ArmModelError(path, f"tool joints {', '.join(j.name for j in tools)}: name one tool "
                                  f"'{TOOL_JOINT}', or several 'tool_<name>', not both")
    out = {}
    for tool in tools:
        chain = [tool]
        while chain[-1].parent in by_child:
            chain.append(by_child[chain[-1].parent])
            if len(chain) > len(joints):
                raise ArmModelError(path, "the joints form a loop")
        out[tool.name] = chain[::-1]
    return out


def read_couplings(axes: list[Joint], source: Path | str, sizes_file: Path | None,
                   couplings: dict[str, Any]) -> dict[str, Coupling]:
    """Return the arm's coupled axes by name: URDF ``<mimic>`` and the sizes file's block.

    Args:
        axes: the arm's axis joints, in axis order.
        source: the URDF file.
        sizes_file: the sizes file, or None (the built-in sizes).
        couplings: the sizes' ``couplings`` block: joint name -> ``{"of": {joint: a}, "offset": b}``.

    Raises:
        ArmModelError: a coupling of a joint that is no axis, one that follows a joint that is no
            axis or is coupled itself, or a joint coupled twice (naming the file and line or key).
    """
    axis_names = [j.name for j in axes]
    out: dict[str, Coupling] = {}
    files: dict[str, Path | str] = {}
    for joint in axes:
        if joint.mimic is not None:
            other, multiplier, offset = joint.mimic
            out[joint.name] = Coupling(joint.name, ((other, multiplier),), offset,
                                       f"line {joint.line}: <mimic> of '{joint.name}'")
            files[joint.name] = source
    sizes = sizes_file or "<sizes>"
    for name, entry in couplings.items():
        if name in out:
            raise ArmModelError(sizes, f"couplings.{name}: '{name}' has a <mimic> already "
                                       f"({source}: {out[name].source}); state it once")
        if name not in axis_names:
            raise ArmModelError(sizes, f"couplings.{name}: '{name}' is not an axis of the arm "
                                       f"(axes: {', '.join(axis_names)})")
        out[name] = Coupling(name, tuple(entry["of"].items()), entry["offset"], f"couplings.{name}")
        files[name] = sizes
    for c in out.values():
        for other, _ in c.terms:
            why = ("is not an axis of the arm" if other not in axis_names else
                   "is coupled itself: write it with the independent joints" if other in out
                   else "")
            if why:
                raise ArmModelError(files[c.joint], f"{c.source}: follows '{other}', which {why}")
    order = {name: k for k, name in enumerate(axis_names)}
    return dict(sorted(out.items(), key=lambda item: order[item[0]]))


def axis_after(joints: list[Joint]) -> np.ndarray | None:
    """Return the axis of the first revolute joint of ``joints`` in the frame before them.

    The origins on the way (nominal geometry, and the revolute's own) rotate it.
    """
    rot = np.eye(3)
    for joint in joints:
        rot = rot @ joint.origin[:3, :3]
        if joint.type in MOVABLE:
            axis: np.ndarray = rot @ joint.axis
            return axis
    return None


def one_entry_per_axis(urdf: UrdfTree) -> UrdfTree:
    """Return the tree with every ``continuous`` joint a ``revolute`` one with wide limits.

    A continuous joint is a revolute joint without limits; Pinocchio's own takes two configuration
    entries (cos, sin), this one entry, its angle, as every other axis. The readout limits stay the
    arm's (:attr:`Arm.joint_limits`: one turn). A tree without continuous joints is returned as is.
    """
    continuous = [j for j in urdf.joints() if j.type == "continuous"]
    if not continuous:
        return urdf
    urdf = urdf.copy()
    for joint in continuous:
        urdf.make_one_dof(joint.name, "revolute", joint.axis, zero_origin=False)
    return urdf


def build_model(urdf: UrdfTree) -> pin.Model:
    """Return Pinocchio's model of a URDF tree, one configuration entry per axis.

    (A ``continuous`` joint as a revolute one: :func:`one_entry_per_axis`.)

    Raises:
        ArmModelError: naming the file and what Pinocchio's URDF parser said, or a chain too
            deep for it (:meth:`UrdfTree.check_depth`).
    """
    urdf.check_depth(" (with the error frames and tool added in memory)")  # else a SIGSEGV
    try:
        return pin.buildModelFromXML(one_entry_per_axis(urdf).xml())
    except (RuntimeError, ValueError) as exc:
        raise ArmModelError(urdf.path, f"Pinocchio cannot build a model from it: {exc}") from None


def tree_order(urdf: UrdfTree) -> dict[str, int]:
    """Return joint name -> rank in the depth-first order in which Pinocchio numbers the tree."""
    model = build_model(urdf)
    kinds = (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT)
    return {f.name: k for k, f in enumerate(model.frames) if f.type in kinds}


def read_error_frame(joint: Joint, next_axis: np.ndarray | None, path: Path | str) -> ErrorFrame:
    """Read one error frame from its fixed joint, checking it holds one elementary transform."""
    match = ERROR_FRAME_PATTERN.match(joint.name)
    assert match is not None
    kind = match.group(1)
    origin = joint.origin
    if kind == "dth":
        if next_axis is None:
            raise ArmModelError(path, f"line {joint.line}: error frame '{joint.name}' has no "
                                      "revolute joint after it")
        axis, is_angle = next_axis, True
    elif kind in _ROT_LETTER:
        axis, is_angle = _UNIT[_ROT_LETTER[kind]], True
    else:
        axis, is_angle = _UNIT[kind[1]], False
    if is_angle:
        omega = pin.log3(origin[:3, :3])
        value = float(omega @ axis)
        bad = np.linalg.norm(omega - value * axis) > 1e-9 or np.linalg.norm(origin[:3, 3]) > _TOL
    else:
        value = float(origin[:3, 3] @ axis)
        bad = (np.linalg.norm(origin[:3, 3] - value * axis) > _TOL
               or np.linalg.norm(origin[:3, :3] - np.eye(3)) > 1e-9)
    if bad:
        what = "rotation about" if is_angle else "translation along"
        raise ArmModelError(path, f"line {joint.line}: error frame '{joint.name}' must hold a pure {what} "
                                  f"{np.round(axis, 6).tolist()} (its origin is {origin.tolist()})")
    return ErrorFrame(joint.name, is_angle, axis, value)
