r"""The arm: a URDF following aacmm_pin's conventions, read with yourdfpy, run on Pinocchio.

Conventions (the default arm ``urdf/aacmm7.urdf`` follows them; a user's arm is another URDF that
does too):

* **Axes.** The revolute joints on the chain from the root link to the stylus are the encoder
  axes A1..An, numbered in chain order.
* **Error frames.** A fixed joint named ``dx<ij>``, ``dy<ij>``, ``dz<ij>`` (translation along x/y/z of
  its parent frame), ``a<ij>``, ``b<ij>``, ``c<ij>`` (right-handed rotation about x/y/z) or
  ``dth<i>0`` (rotation about the axis of the next revolute joint: the axis offset) holds one
  elementary transform of the paper's Eq. (2); its origin holds the parameter's value.
* **Tool.** The fixed joint ``tool`` carries the stylus sphere centre (the tool vector
  :math:`{}^7p`) in the last axis' frame; its child link is the stylus.
* Every other fixed joint is nominal geometry (e.g. ``L2z``).

Two Pinocchio views of one arm:

* the *runtime* model (:meth:`Arm.runtime_model`): error frames fixed at given values, one
  configuration entry per axis, for robotics stacks and prediction;
* the *identification* model (:attr:`Arm.identification`): every error frame, the tool vector and
  the r-CS -> MT-CS transform (paper Eq. 4, :math:`D_b(\beta_0) D_a(\alpha_0) D_c(\gamma_0)` plus a
  translation) are 1-DOF joints, so that Pinocchio's frame Jacobian of the stylus gives
  d(stylus)/d(every parameter) analytically.
"""

from __future__ import annotations

import copy
import hashlib
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
import yourdfpy

from aacmm_pin.errors import ArmModelError, FrameNotFound
from aacmm_pin.sizes import Sizes, sizes_of_urdf, sizes_path

DEFAULT_ARM = "aacmm7"
ERROR_FRAME_PATTERN = re.compile(r"^(dth|dx|dy|dz|a|b|c)(\d+)$")
TOOL_JOINT = "tool"
BASE_JOINTS = ("mt_x", "mt_y", "mt_z", "beta0", "alpha0", "gamma0")
"""Identification-model joints of the r-CS -> MT-CS transform, root first (Eq. 4)."""
TOOL_JOINTS = ("tool_x", "tool_y", "tool_z")
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


EMBEDDED = ("aacmm7", "ur5", "wam7")
"""Arms shipped with the package, loadable by name: the default AACMM and the two robots of the
public laser-tracker data (``urdf/make_serial_dh.py`` writes them from the makers' DH tables)."""


def resolve_arm_path(arm: str | Path) -> Path:
    """Return the URDF path of an arm given by path or by the name of an embedded arm.

    Raises:
        ArmModelError: if it is neither an existing file nor an embedded arm's name.
    """
    path = Path(arm)
    if path.is_file():
        return path
    name = str(arm)
    candidates = [resources.files("aacmm_pin") / "urdf" / f"{name}.urdf",
                  Path(__file__).resolve().parents[1] / "urdf" / f"{name}.urdf"]
    for candidate in candidates:
        if candidate.is_file():
            return Path(str(candidate))
    raise ArmModelError(arm, f"no such URDF file, and no embedded arm named '{name}' "
                             f"(embedded: {', '.join(EMBEDDED)})")


def _chain(robot: yourdfpy.Robot, path: Path | str) -> list[yourdfpy.Joint]:
    """Return the joints from the root link to the tool joint, root first."""
    by_child = {j.child: j for j in robot.joints}
    tool = [j for j in robot.joints if j.name == TOOL_JOINT]
    if not tool:
        raise ArmModelError(path, f"no fixed joint named '{TOOL_JOINT}' carrying the stylus "
                                  f"(joints: {', '.join(j.name for j in robot.joints)})")
    chain = [tool[0]]
    while chain[-1].parent in by_child:
        chain.append(by_child[chain[-1].parent])
        if len(chain) > len(robot.joints):
            raise ArmModelError(path, "the joints form a loop")
    return chain[::-1]


def _error_frame(joint: yourdfpy.Joint, next_axis: np.ndarray | None, path: Path | str
                 ) -> ErrorFrame:
    """Read one error frame from its fixed joint, checking it holds one elementary transform."""
    match = ERROR_FRAME_PATTERN.match(joint.name)
    assert match is not None
    kind = match.group(1)
    origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)
    if kind == "dth":
        if next_axis is None:
            raise ArmModelError(path, f"error frame '{joint.name}' has no revolute joint after it")
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
        raise ArmModelError(path, f"error frame '{joint.name}' must hold a pure {what} "
                                  f"{np.round(axis, 6).tolist()} (its origin is {origin.tolist()})")
    return ErrorFrame(joint.name, is_angle, axis, value)


class Arm:
    """An AACMM: its URDF, its axes, error frames and tool, and its Pinocchio models.

    Use :func:`load_arm` to make one.
    """

    def __init__(self, urdf: yourdfpy.URDF, source: Path | str, name: str):
        self.source = source
        """Where the URDF came from (path)."""
        self.name = name
        """Arm name as given by the user: an embedded arm's name or a URDF path."""
        self._robot = urdf.robot
        chain = _chain(self._robot, source)
        self._chain_joints = chain
        self.axis_names: list[str] = [j.name for j in chain if j.type in ("revolute", "continuous")]
        """Revolute joints (encoder axes) in chain order: axis n is ``axis_names[n - 1]``."""
        if not self.axis_names:
            raise ArmModelError(source, "no revolute joint between the root link and the tool")
        frames = []
        for i, joint in enumerate(chain):
            if joint.type == "fixed" and ERROR_FRAME_PATTERN.match(joint.name):
                nxt = next((j for j in chain[i + 1:] if j.type in ("revolute", "continuous")), None)
                frames.append(_error_frame(joint, None if nxt is None else
                                           np.asarray(nxt.axis, dtype=float), source))
            elif joint.type not in ("fixed", "revolute", "continuous"):
                raise ArmModelError(source, f"joint '{joint.name}' is {joint.type}; an AACMM chain "
                                            "holds only revolute and fixed joints")
        self.error_frames: list[ErrorFrame] = frames
        """The DH error parameters in chain order."""
        tool_origin = chain[-1].origin if chain[-1].origin is not None else np.eye(4)
        self.nominal_tool: np.ndarray = np.asarray(tool_origin, dtype=float)[:3, 3].copy()
        """Tool vector held by the URDF, shape (3,), in m, in the last axis' frame."""
        self.stylus_link: str = chain[-1].child
        """Name of the stylus link (child of the tool joint)."""
        self.root_link: str = chain[0].parent
        """Name of the root link (the reference CS, r-CS)."""

    def __reduce__(self) -> tuple[Callable[[str, str], Arm], tuple[str, str]]:
        """Pickle as the URDF path and name (reloaded on the other side, e.g. in a worker)."""
        return (_load_named, (str(self.source), self.name))

    # ------------------------------------------------------------------ names
    @property
    def n_axes(self) -> int:
        """Number of encoder axes."""
        return len(self.axis_names)

    @property
    def error_names(self) -> list[str]:
        """Names of the DH error parameters, chain order."""
        return [f.name for f in self.error_frames]

    @property
    def nominal_errors(self) -> dict[str, float]:
        """Values the URDF holds in its error frames (m or rad)."""
        return {f.name: f.nominal for f in self.error_frames}

    def error_frame(self, name: str) -> ErrorFrame:
        """Return the error frame of this name.

        Raises:
            FrameNotFound: if the arm has no such error frame.
        """
        for frame in self.error_frames:
            if frame.name == name:
                return frame
        raise FrameNotFound(name, self.error_names)

    @cached_property
    def sizes(self) -> Sizes:
        """Plausible sizes of the arm's errors (:mod:`aacmm_pin.sizes`), read once.

        From the sizes file beside the URDF (``<name>.sizes.json``); the default AACMM's where
        there is none.

        Raises:
            FileFormatError: if the sizes file is malformed (naming the file and the key).
        """
        return sizes_of_urdf(self.source)

    @cached_property
    def joint_limits(self) -> np.ndarray:
        """Lower and upper readout limits of each axis, shape (n_axes, 2), in rad."""
        out = np.tile([-np.pi, np.pi], (self.n_axes, 1))
        for i, name in enumerate(self.axis_names):
            joint = next(j for j in self._chain_joints if j.name == name)
            if joint.type == "revolute" and joint.limit is not None:
                out[i] = [joint.limit.lower, joint.limit.upper]
        return out

    # ------------------------------------------------------------------ URDF views
    def urdf_robot(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None
                   ) -> yourdfpy.Robot:
        """Return a copy of the URDF description with error frames and tool set to these values.

        Args:
            dh: error frame name -> value (m or rad); missing names keep the URDF's values.
            tool: tool vector, shape (3,), in m; None keeps the URDF's.

        Raises:
            FrameNotFound: if ``dh`` names a parameter the arm does not have.
        """
        dh = dict(dh or {})
        for name in dh:
            if name not in self.error_names:
                raise FrameNotFound(name, self.error_names)
        robot = copy.deepcopy(self._robot)
        for joint in robot.joints:
            if joint.name in dh:
                joint.origin = self.error_frame(joint.name).transform(dh[joint.name])
            elif joint.name == TOOL_JOINT and tool is not None:
                origin = np.eye(4) if joint.origin is None else np.array(joint.origin, dtype=float)
                origin[:3, 3] = np.asarray(tool, dtype=float).reshape(3)
                joint.origin = origin
        return robot

    def urdf_string(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None
                    ) -> str:
        """Return the URDF text with error frames and tool set to these values."""
        return _to_xml(self.urdf_robot(dh, tool))

    def runtime_model(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None
                      ) -> pin.Model:
        """Return the runtime Pinocchio model: error frames fixed at these values.

        Its configuration is the n_axes true joint angles (readouts already corrected by the
        encoder maps, see :func:`aacmm_pin.encoder_map.correct_readouts`); frame ``stylus_link``
        is the stylus sphere centre.
        """
        return pin.buildModelFromXML(self.urdf_string(dh, tool))

    @cached_property
    def identification(self) -> IdentificationModel:
        """The identification model (built once)."""
        return IdentificationModel(self)


class IdentificationModel:
    """Pinocchio model in which every parameter is a 1-DOF joint along its own axis.

    Joint order (root first): the r-CS -> MT-CS translation ``mt_x, mt_y, mt_z`` and rotation
    ``beta0, alpha0, gamma0`` (Eq. 4), then the arm's chain with axes and error frames, then the
    tool vector ``tool_x, tool_y, tool_z``. Every joint has one configuration entry, so ``nq == nv``.
    """

    def __init__(self, arm: Arm):
        robot = copy.deepcopy(arm._robot)
        by_name = {f.name: f for f in arm.error_frames}
        big = yourdfpy.Limit(effort=0.0, velocity=1.0, lower=-1e3, upper=1e3)
        for joint in robot.joints:
            if joint.name in by_name:
                frame = by_name[joint.name]
                joint.type = "revolute" if frame.is_angle else "prismatic"
                joint.axis = frame.axis.copy()
                joint.origin = np.eye(4)
                joint.limit = big
            elif joint.type in ("revolute", "continuous"):
                joint.type, joint.limit = "revolute", big
        tool = next(j for j in robot.joints if j.name == TOOL_JOINT)
        robot.joints.remove(tool)
        parent = tool.parent
        for i, name in enumerate(TOOL_JOINTS):
            child = tool.child if i == 2 else f"{name}_frame"
            robot.joints.append(yourdfpy.Joint(name=name, type="prismatic", parent=parent,
                                               child=child, origin=np.eye(4),
                                               axis=np.eye(3)[i], limit=big))
            if i < 2:
                robot.links.append(yourdfpy.Link(name=child))
            parent = child
        parent = "mt"
        robot.links.append(yourdfpy.Link(name="mt"))
        for i, name in enumerate(BASE_JOINTS):
            child = arm.root_link if i == 5 else f"{name}_frame"
            axis = np.eye(3)[[0, 1, 2, 1, 0, 2][i]]
            robot.joints.append(yourdfpy.Joint(name=name, type="prismatic" if i < 3 else "revolute",
                                               parent=parent, child=child, origin=np.eye(4),
                                               axis=axis, limit=big))
            if i < 5:
                robot.links.append(yourdfpy.Link(name=child))
            parent = child
        self.model: pin.Model = pin.buildModelFromXML(_to_xml(robot))
        """The Pinocchio model."""
        self._local = threading.local()
        self.stylus_frame: int = self.model.getFrameId(arm.stylus_link)
        """Pinocchio frame id of the stylus sphere centre."""
        idx = {name: self.model.joints[self.model.getJointId(name)].idx_q
               for name in self.model.names[1:]}
        self.base_idx: np.ndarray = np.array([idx[n] for n in BASE_JOINTS])
        """Configuration indices of (mt_x, mt_y, mt_z, beta0, alpha0, gamma0)."""
        self.axis_idx: np.ndarray = np.array([idx[n] for n in arm.axis_names])
        """Configuration indices of the axes A1..An."""
        self.error_idx: np.ndarray = np.array([idx[n] for n in arm.error_names], dtype=int)
        """Configuration indices of the error frames, in ``arm.error_names`` order."""
        self.tool_idx: np.ndarray = np.array([idx[n] for n in TOOL_JOINTS])
        """Configuration indices of the tool vector (x, y, z)."""
        assert self.model.nq == self.model.nv == len(idx)

    @property
    def data(self) -> pin.Data:
        """The model's workspace, one per thread (Pinocchio's Data is not shared safely)."""
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        return data


def _to_xml(robot: yourdfpy.Robot) -> str:
    """Serialise a yourdfpy robot description to URDF text."""
    text = yourdfpy.URDF(robot=robot, build_scene_graph=False, load_meshes=False).write_xml_string()
    return text.decode() if isinstance(text, bytes) else text


def load_arm(arm: str | Path = DEFAULT_ARM) -> Arm:
    """Load an arm from a URDF path or an embedded arm's name (default: ``aacmm7``).

    Raises:
        ArmModelError: if the file cannot be read or breaks the conventions (message names the
            file, and the line and column for XML syntax errors).
    """
    path = resolve_arm_path(arm)
    try:  # strict syntax check first: yourdfpy silently recovers from broken XML
        ElementTree.parse(path)
    except ElementTree.ParseError as exc:
        line, column = exc.position
        raise ArmModelError(path, f"line {line}, column {column + 1}: invalid XML: {exc}") from None
    try:
        urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False,
                                  build_collision_scene_graph=False, load_collision_meshes=False)
    except Exception as exc:  # lxml syntax errors carry line/column; others name the problem
        lineno = getattr(exc, "lineno", None)
        where = f" (line {lineno}, column {getattr(exc, 'offset', '?')})" if lineno else ""
        raise ArmModelError(path, f"cannot read URDF{where}: {exc}") from exc
    return Arm(urdf, path, str(arm))


_LOADED: dict[tuple[str, str, str], Arm] = {}


def _load_named(path: str, name: str) -> Arm:
    """Load (once per process) the arm of a URDF path and keep the user's name for it."""
    sizes = sizes_path(path)  # an edited URDF or sizes file reloads
    data = Path(path).read_bytes() + (sizes.read_bytes() if sizes.is_file() else b"")
    key = (path, name, hashlib.sha1(data).hexdigest())
    if key not in _LOADED:
        arm = load_arm(path)
        arm.name = name
        _LOADED[key] = arm
    return _LOADED[key]
