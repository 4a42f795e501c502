r"""A robot's own URDF made calibratable as it is: the tool frame chosen by name, error frames added.

A ROS-style URDF (a robot-description package's, e.g. example-robot-data's UR5) names its flange
``tool0`` and holds no error frames. :func:`load_arm <aacmm_pin.model.arm.load_arm>` completes such
a file in memory, the user's links and joints kept with their names and origins:

* **The tool.** Without a fixed joint ``tool`` or ``tool_<name>``, the measured point (a laser
  tracker's SMR, a stylus) hangs off a link named by the user (``--tool-frame LINK``,
  ``load_arm(..., tool_frame=)``), by default ``tool0`` when the URDF has such a link: a fixed
  joint ``tool`` (identity origin) from that link to a new link ``<link>_point``. The tool vector
  (what the fit identifies) is the point in that link's frame; the link itself stays where the URDF
  puts it.
* **Error frames.** Without error frames on the tools' chains, six are added before each axis k
  (1..n, in axis order), in its parent link's frame: fixed joints ``dx<k> dy<k> dz<k> a<k> b<k>
  c<k>`` at the identity, each with its own empty child link ``<joint>_frame``, and the axis'
  joint hangs off the last of them. Together they model every error of the joint's placement
  (three translations, three rotations); the directions the data cannot see (a base rotation
  about the first axis, a translation along an axis that the next parallel one absorbs, ...) are
  held at zero by the identification (:mod:`aacmm_pin.fit.identifiability`).

The completed URDF is what the package uses and writes (``calibrated.urdf``, ``aacmm-pin axes URDF
--write-error-frames OUT``): loaded again it needs no option. Units as in URDF: m and rad.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aacmm_pin.errors import ArmModelError
from aacmm_pin.model.urdf_tree import Joint, UrdfTree

DEFAULT_TOOL_FRAME = "tool0"
"""The tool frame of a ROS-style URDF (REP 199: the flange, without end-effector)."""
POINT_SUFFIX = "_point"
"""The measured point's link: ``<tool frame>_point``, child of the added joint ``tool``."""
ERROR_KINDS = ("dx", "dy", "dz", "a", "b", "c")
"""The error frames added before each axis, in chain order: three translations along and three
rotations about x, y, z of the axis' parent link."""
FRAME_SUFFIX = "_frame"
"""An added error frame's child link: ``<joint>_frame``."""
_TOOL = re.compile(r"^tool(?:_([A-Za-z0-9][A-Za-z0-9_]*))?$")
_MOVABLE = ("revolute", "continuous")


@dataclass(frozen=True)
class Completion:
    """What :func:`add_tool_joint` and :func:`add_error_frames` added to a URDF in memory."""

    tool_frame: str | None = None
    """The link the joint ``tool`` was added on; None when the URDF names its own tool joint."""
    error_frames: tuple[str, ...] = ()
    """The error frames added (joint names, chain order); empty when the URDF has its own."""
    axes: tuple[str, ...] = ()
    """The axes (joint names, axis order) the error frames were added before."""

    def note(self, source: str | Path) -> str | None:
        """Return one line saying what was added to the URDF ``source``, None when nothing was."""
        parts = []
        if self.error_frames:
            counts = {a: sum(1 for n in self.error_frames
                             if re.fullmatch(rf"[a-z]+{k}", n)) for k, a in enumerate(self.axes, 1)}
            names = (" ... ".join((self.axes[0], self.axes[-1])) if len(self.axes) > 1
                     else self.axes[0])
            most = max(counts.values())
            fewer = [f"{c or 'none'} before {a}" for a, c in counts.items() if c != most]
            where = (f"the complete set of its {len(self.axes)} axes ({names}): {most} before "
                     f"each" + (f", {', '.join(fewer)} (other parameters move the arm alike)"
                                if fewer else ""))
            parts.append(f"{Path(source).name} has no error frames: added "
                         f"{len(self.error_frames)}, {where}")
        if self.tool_frame is not None:
            tool = f"tool: the point on {self.tool_frame} (joint 'tool')"
            parts.append(tool if parts else f"{Path(source).name}: {tool}")
        return "; ".join(parts) or None


def _leaf_candidates(joints: list[Joint]) -> list[str]:
    """Return the leaf links whose chain from the root holds a revolute joint (tool frames)."""
    by_child = {j.child: j for j in joints}
    parents = {j.parent for j in joints}
    out = []
    for joint in joints:
        if joint.child in parents:
            continue
        chain: Joint | None = joint
        seen = 0
        while chain is not None and seen <= len(joints):
            if chain.type in _MOVABLE:
                out.append(joint.child)
                break
            chain, seen = by_child.get(chain.parent), seen + 1
    return out


def _check_free(urdf: UrdfTree, joints: list[Joint], names: list[str], links: list[str],
                why: str) -> None:
    """Raise if a joint or link to be added is named like an existing one."""
    taken_joints = {j.name for j in joints}
    taken_links = set(urdf.links)
    clash = ([f"joint '{n}'" for n in names if n in taken_joints]
             + [f"link '{n}'" for n in links if n in taken_links])
    if clash:
        raise ArmModelError(urdf.path, f"{why}: the URDF has a {', '.join(clash)} already; "
                                       "rename it, or add the tool and error frames yourself")


def add_tool_joint(urdf: UrdfTree, tool_frame: str | None = None) -> tuple[UrdfTree, str | None]:
    """Return the URDF with a fixed joint ``tool`` on the tool frame, when it names no tool.

    Args:
        urdf: the URDF as read (not edited: a copy is returned when a joint is added).
        tool_frame: the link the measured point hangs off; None: ``tool0`` if the URDF has such a
            link. Only for a URDF without a ``tool`` or ``tool_<name>`` fixed joint.

    Returns:
        The (completed) URDF and the tool frame used (None: the URDF names its own tool).

    Raises:
        ArmModelError: one line naming the file, for a ``tool_frame`` given to a URDF with its own
            tool joint, an unknown link, no ``tool0`` and no ``tool_frame`` (listing the candidate
            links: leaves of chains holding a revolute joint), or a name clash.
    """
    joints = urdf.joints()
    own = [j.name for j in joints if j.type == "fixed" and _TOOL.match(j.name)]
    if own:
        if tool_frame is not None:
            raise ArmModelError(urdf.path, f"tool frame '{tool_frame}' given, but the URDF names "
                                           f"its tool joint{'s' * (len(own) > 1)} "
                                           f"({', '.join(own)}); leave the tool frame out")
        return urdf, None
    links = urdf.links
    candidates = _leaf_candidates(joints)
    hint = (f"candidate links (leaves after a revolute joint): {', '.join(candidates)}"
            if candidates else "no link follows a revolute joint")
    if tool_frame is None:
        if DEFAULT_TOOL_FRAME not in links:
            raise ArmModelError(urdf.path, f"no fixed joint 'tool' (or 'tool_<name>') and no link "
                                           f"'{DEFAULT_TOOL_FRAME}': name the link the measured "
                                           f"point hangs off with --tool-frame LINK ({hint})")
        tool_frame = DEFAULT_TOOL_FRAME
    elif tool_frame not in links:
        raise ArmModelError(urdf.path, f"tool frame '{tool_frame}' is no link of the URDF ({hint})")
    point = f"{tool_frame}{POINT_SUFFIX}"
    _check_free(urdf, joints, ["tool"], [point], "cannot add the tool joint")
    urdf = urdf.copy()
    urdf.insert_fixed("tool", tool_frame, point)
    return urdf, tool_frame


def _previous_axes(joints: list[Joint], axes: list[str]) -> dict[str, tuple[str, np.ndarray] | None]:
    """Return axis -> (the previous axis on its chain, that axis' direction in its parent link).

    None for an axis with no axis before it. The direction is a unit vector in the frame of the
    axis' parent link (where its error frames sit), through the fixed origins on the way.
    """
    by_child = {j.child: j for j in joints}
    parent_of = {j.name: j.parent for j in joints}
    out: dict[str, tuple[str, np.ndarray] | None] = {}
    for axis in axes:
        link, rot, found = parent_of[axis], np.eye(3), None
        for _ in range(len(joints)):
            joint = by_child.get(link)
            if joint is None:
                break
            if joint.name in axes:
                found = (joint.name, rot.T @ joint.axis)
                break
            rot = joint.origin[:3, :3] @ rot
            link = joint.parent
        out[axis] = found
    return out


def error_frame_kinds(joints: list[Joint], axes: list[str]) -> dict[str, tuple[str, ...]]:
    """Return axis -> the error frames (kinds of :data:`ERROR_KINDS`) a complete minimal set adds.

    Six before every axis model any error of its placement; some are the same motion as another
    parameter's, whatever the data:

    * before the first axis (the only one with no axis before it), all six: the instrument frame
      X0 (six unknowns) moves the whole arm alike;
    * before an axis whose previous axis (the only one after it) points along a coordinate axis of
      the parent link, the translation along and the rotation about that direction: they commute
      with the previous joint, so the previous axis' own error frames hold them.

    Every other error frame is kept (a direction the data still cannot see is held at its start
    value by the identification).
    """
    previous = _previous_axes(joints, axes)
    followers: dict[str, int] = {}
    for entry in previous.values():
        if entry is not None:
            followers[entry[0]] = followers.get(entry[0], 0) + 1
    roots = [a for a in axes if previous[a] is None]
    out: dict[str, tuple[str, ...]] = {}
    for axis in axes:
        entry = previous[axis]
        drop: set[str] = set()
        if entry is None:
            if len(roots) == 1:
                drop = set(ERROR_KINDS)
        elif followers[entry[0]] == 1:
            direction = entry[1]
            i = int(np.argmax(np.abs(direction)))
            if abs(abs(direction[i]) - 1.0) < 1e-9:
                drop = {ERROR_KINDS[i], ERROR_KINDS[3 + i]}
        out[axis] = tuple(k for k in ERROR_KINDS if k not in drop)
    return out


def add_error_frames(urdf: UrdfTree, axes: list[str], minimal: bool = True
                     ) -> tuple[UrdfTree, tuple[str, ...]]:
    """Return a copy of the URDF with error frames before each axis (see the module doc).

    Args:
        urdf: the URDF (with its tool joint), not edited.
        axes: the axes' joint names in axis order (:attr:`aacmm_pin.model.arm.Arm.axis_names`).
        minimal: leave out the error frames that are another parameter's motion whatever the data
            (:func:`error_frame_kinds`); False: six before every axis.

    Returns:
        The completed URDF and the added error frames' names, chain order.

    Raises:
        ArmModelError: one line naming the file, if an added name is taken by a joint or link.
    """
    joints = urdf.joints()
    kinds = (error_frame_kinds(joints, axes) if minimal
             else dict.fromkeys(axes, ERROR_KINDS))
    names = [f"{kind}{k}" for k, axis in enumerate(axes, start=1) for kind in kinds[axis]]
    _check_free(urdf, joints, names, [n + FRAME_SUFFIX for n in names],
                "cannot add the error frames")
    parent_of = {j.name: j.parent for j in joints}
    urdf = urdf.copy()
    for k, axis in enumerate(axes, start=1):
        parent = parent_of[axis]
        for kind in kinds[axis]:
            name = f"{kind}{k}"
            urdf.insert_fixed(name, parent, name + FRAME_SUFFIX, before=axis)
            parent = name + FRAME_SUFFIX
        if parent != parent_of[axis]:
            urdf.set_parent(axis, parent)
    return urdf, tuple(names)
