r"""The arm: a URDF following aacmm_pin's conventions, read as an XML tree, run on Pinocchio.

Conventions (the default arm ``urdf/aacmm7.urdf`` follows them; a user's arm is another URDF that
does too):

* **Tools.** A fixed joint named ``tool`` carries the stylus sphere centre (the tool vector
  :math:`{}^7p`) in its parent frame (the last axis' frame); its child link is the stylus. A tree
  (e.g. a torso with two arms, a marker on each hand) has several tools instead, fixed joints named
  ``tool_<name>`` (``tool_left``, ``tool_right``): either one ``tool`` or ``tool_<name>`` joints. A
  tool's *name* (``tool_names``, the ``tool`` column of ``points.csv``) is ``<name>``, or ``tool``
  for the single ``tool`` joint; its vector's unknowns are ``<joint>_x``, ``<joint>_y``,
  ``<joint>_z`` (``tool_x``, ``tool_left_x``).
* **Axes.** The revolute (or continuous) joints on the union of the chains from the root link to
  the tools are the encoder axes A1..An, in the depth-first order of the kinematic tree in which
  Pinocchio numbers the joints of the URDF (for a serial arm: root to tool, chain order); this is
  the order of the readout columns ``q1_deg..qn_deg`` (``aacmm-pin axes URDF`` prints it). Tools
  are in that order too. Movable joints on no tool's chain are held fixed at zero in the models
  below (they do not move any tool), so that the configuration is exactly the n readouts.
* **Error frames.** A fixed joint named ``dx<ij>``, ``dy<ij>``, ``dz<ij>`` (translation along x/y/z of
  its parent frame), ``a<ij>``, ``b<ij>``, ``c<ij>`` (right-handed rotation about x/y/z) or
  ``dth<i>0`` (rotation about the axis of the next revolute joint down its branch, through the
  rotations on the way: the axis offset; before a branch point, the same axis on every branch)
  holds one elementary transform of the paper's Eq. (2); its origin holds the parameter's value.
  Error frames are the ones on the tools' chains, in the same depth-first order as the axes.
* Every other fixed joint is nominal geometry (e.g. ``L2z``).
* **A robot's own URDF** (ROS-style: ``tool0``, no error frames) is completed in memory by
  :func:`load_arm`: a ``tool`` joint on the tool frame named by ``tool_frame`` (default ``tool0``)
  and error frames before the axes (:mod:`aacmm_pin.model.urdf_completion`).
* **Coupled joints.** An axis whose angle follows others' (a passive joint, no encoder) is stated
  by a URDF ``<mimic joint multiplier offset>`` or, for a sum of several joints, by the
  ``couplings`` block of the arm's sizes file (:mod:`aacmm_pin.data.couplings`): it keeps its axis
  number and readout column (which may be left out of the files, :attr:`Arm.axis_couplings`), but
  its angle is :math:`\sum_i a_i q_i + b` of the independent axes' true angles plus its own angle
  errors (e.g. its compliance), :meth:`Arm.couple`. Pinocchio's models keep the joint free (one
  configuration entry per axis, as every other); the coupling is applied in this package's layer.

Two Pinocchio views of one arm:

* the *runtime* model (:meth:`Arm.runtime_model`): error frames fixed at given values, one
  configuration entry per axis, for robotics stacks and prediction;
* the *identification* model (:attr:`Arm.identification`): every error frame, the tool vector and
  the r-CS -> MT-CS transform (paper Eq. 4, :math:`D_b(\beta_0) D_a(\alpha_0) D_c(\gamma_0)` plus a
  translation) are 1-DOF joints, so that Pinocchio's frame Jacobian of the stylus gives
  d(stylus)/d(every parameter) analytically (of each tool's frame: the joints not on its chain,
  e.g. the other tools' vectors, have zero columns).
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from aacmm_pin.data.couplings import AxisCoupling, Coupling, fill_coupled
from aacmm_pin.errors import ArmModelError, FrameNotFound
from aacmm_pin.model._chain import BatchedChain
from aacmm_pin.model.arm_files import EMBEDDED as EMBEDDED  # re-exported: the embedded arms
from aacmm_pin.model.arm_files import resolve_arm_path as resolve_arm_path
from aacmm_pin.model.arm_files import resolve_sizes_path
from aacmm_pin.model.arm_frames import ERROR_FRAME_PATTERN as ERROR_FRAME_PATTERN  # re-exported
from aacmm_pin.model.arm_frames import (
    MOVABLE,
    TOOL_PATTERN,
    axis_after,
    read_couplings,
    read_error_frame,
    tool_chains,
    tree_order,
)
from aacmm_pin.model.arm_frames import TOOL_JOINT as TOOL_JOINT
from aacmm_pin.model.arm_frames import ErrorFrame as ErrorFrame
from aacmm_pin.model.arm_frames import build_model as build_model
from aacmm_pin.model.arm_frames import one_entry_per_axis as one_entry_per_axis
from aacmm_pin.model.sizes import DEFAULT as DEFAULT_SIZES
from aacmm_pin.model.sizes import Sizes, read_sizes, sizes_file
from aacmm_pin.model.urdf_completion import Completion, add_error_frames, add_tool_joint
from aacmm_pin.model.urdf_tree import UrdfTree, read_urdf

if TYPE_CHECKING:
    import yourdfpy

DEFAULT_ARM = "aacmm7"
BASE_JOINTS = ("mt_x", "mt_y", "mt_z", "beta0", "alpha0", "gamma0")
"""Identification-model joints of the r-CS -> MT-CS transform, root first (Eq. 4)."""
TOOL_JOINTS = ("tool_x", "tool_y", "tool_z")
"""Identification-model joints of the tool vector of the single ``tool`` joint."""
COUPLING_TOLERANCE = 5.0
r"""A readout column given for a coupled joint may differ from its coupling by this many of the
arm's plausible angle errors (the largest of ``dh_angle``, ``map_node`` and the encoder effect's
size, :mod:`aacmm_pin.model.sizes`) times :math:`\sqrt{1 + \sum a_i^2}` (every readout in the sum
has its error): a wrong coupling or column is off by degrees."""


class Arm:
    """An arm (an AACMM, a robot): its URDF, its axes, error frames and tools, its Pinocchio models.

    Use :func:`load_arm` to make one.
    """

    def __init__(self, urdf: UrdfTree, source: Path | str, name: str, *,
                 sizes: Path | str | None = None, completion: Completion | None = None):
        self.source = source
        """Where the URDF came from (path)."""
        self.name = name
        """Arm name as given by the user: an embedded arm's name or a URDF path."""
        self.sizes_file: Path | None = Path(sizes) if sizes is not None else sizes_file(source)
        """The sizes file the arm uses (given, else the one beside the URDF); None: defaults."""
        self._sizes_given = sizes is not None
        self.completion: Completion = completion or Completion()
        """What :func:`load_arm` added to the URDF in memory (tool joint, error frames)."""
        self._urdf = urdf
        all_joints = urdf.joints()
        chains = tool_chains(all_joints, source)
        rank = tree_order(urdf)
        on_chain = {j.name: j for chain in chains.values() for j in chain}
        joints = sorted(on_chain.values(), key=lambda j: rank[j.name])
        self._joints = {j.name: j for j in all_joints}
        self.axis_names: list[str] = [j.name for j in joints if j.type in MOVABLE]
        """Encoder axes (revolute joints on the tools' chains) in tree order (see the module
        docstring): axis n is ``axis_names[n - 1]``, readout column ``q<n>_deg``."""
        if not self.axis_names:
            tools = ", ".join(f"'{j.parent}' ('{j.name}')" for c in chains.values()
                              for j in c[-1:])
            raise ArmModelError(source, f"nothing to calibrate: no revolute joint between the root "
                                        f"link and the tool frame {tools}")
        self.tool_joints: list[str] = sorted(chains, key=rank.__getitem__)
        """The tool joints (``tool`` or ``tool_<name>``), in tree order."""
        self.off_chain: list[str] = [j.name for j in all_joints
                                     if j.type != "fixed" and j.name not in on_chain]
        """Movable joints on no tool's chain: held fixed at zero in the Pinocchio models."""
        next_axis: dict[str, np.ndarray | None] = {}
        for chain in chains.values():
            for i, joint in enumerate(chain):
                if joint.type == "fixed" and ERROR_FRAME_PATTERN.match(joint.name):
                    is_dth = joint.name.startswith("dth")  # only its axis is the next one's
                    axis = axis_after(chain[i + 1:]) if is_dth else None
                    seen = next_axis.setdefault(joint.name, axis)
                    if (seen is None) != (axis is None) or (
                            seen is not None and axis is not None and not np.allclose(seen, axis)):
                        raise ArmModelError(source, f"line {joint.line}: error frame "
                                                    f"'{joint.name}' sits before a branch whose "
                                                    "next revolute axes differ")
                elif joint.type not in ("fixed", *MOVABLE):
                    raise ArmModelError(source, f"line {joint.line}: joint '{joint.name}' is "
                                                f"{joint.type} on the chain to the tool; "
                                                "only revolute, continuous and fixed joints "
                                                "can be calibrated")
        self.couplings: dict[str, Coupling] = read_couplings(
            [self._joints[n] for n in self.axis_names], self.source, self.sizes_file,
            self.sizes.couplings)
        """Coupled joint name -> its coupling (URDF ``<mimic>`` and the sizes file's
        ``couplings``), in axis order."""
        n = self.n_axes
        index = {name: i for i, name in enumerate(self.axis_names)}
        self.coupled: np.ndarray = np.array([name in self.couplings for name in self.axis_names])
        """Per axis, whether it is coupled (no encoder, its angle follows others'), (n_axes,)."""
        self.coupling_matrix: np.ndarray = np.eye(n)
        """T, shape (n_axes, n_axes): the joint angles are ``T u + b`` for per-axis angles u
        (independent axes: their true angles; coupled axes: their own angle errors)."""
        self.coupling_offset: np.ndarray = np.zeros(n)
        """b, shape (n_axes,), rad (zero but on coupled axes)."""
        for name, c in self.couplings.items():
            for other, a in c.terms:
                self.coupling_matrix[index[name], index[other]] += a
            self.coupling_offset[index[name]] = c.offset
        self.error_frames: list[ErrorFrame] = [read_error_frame(j, next_axis[j.name], source)
                                               for j in joints if j.name in next_axis]
        """The DH error parameters in tree order (chain order for a serial arm)."""
        self.nominal_tools: dict[str, np.ndarray] = {
            name: chains[name][-1].origin[:3, 3].copy() for name in self.tool_joints}
        """Tool joint -> tool vector held by the URDF, shape (3,), in m, in its parent's frame."""
        self.nominal_tool: np.ndarray = self.nominal_tools[self.tool_joints[0]]
        """Tool vector of the first (for a serial arm: the only) tool, shape (3,), in m."""
        self.tool_links: list[str] = [chains[name][-1].child for name in self.tool_joints]
        """The tools' links (children of the tool joints), in tool order."""
        self.stylus_link: str = self.tool_links[0]
        """Name of the (first) stylus link (child of the tool joint)."""
        self.root_link: str = joints[0].parent
        """Name of the root link (the reference CS, r-CS)."""

    def __reduce__(self) -> tuple[Callable[..., Arm], tuple[str, str, str | None, str | None, bool]]:
        """Pickle as the URDF path, name, tool frame, sizes file and error frames (or none).

        A worker reloads the arm alike (a compact URDF without error frames added).
        """
        return (_load_named, (str(self.source), self.name, self.completion.tool_frame,
                              str(self.sizes_file) if self._sizes_given else None,
                              bool(self.error_frames)))

    @property
    def note(self) -> str | None:
        """One line saying what :func:`load_arm` added to the URDF, None when nothing."""
        return self.completion.note(self.source)

    @property
    def sizes_label(self) -> str:
        """Which sizes the arm uses, for a line or a report: the file's path or the defaults."""
        return str(self.sizes_file) if self.sizes_file is not None else "built-in defaults"

    # ------------------------------------------------------------------ couplings
    @property
    def measured_axes(self) -> list[int]:
        """The axes with an encoder (all but the coupled ones), 1-based."""
        return [a + 1 for a in range(self.n_axes) if not self.coupled[a]]

    @cached_property
    def axis_couplings(self) -> tuple[AxisCoupling, ...]:
        """The coupled axes as the campaign readers see them (0-based axes, a tolerance, rad).

        A readout column given for a coupled axis is checked against its coupling with the
        tolerance :data:`COUPLING_TOLERANCE` times the arm's plausible angle error; a missing one
        is filled.
        """
        index = {name: i for i, name in enumerate(self.axis_names)}
        angle = max(self.sizes.dh_angle, self.sizes.map_node, self.sizes.effects["encoder"])
        return tuple(AxisCoupling(index[c.joint], tuple((index[o], a) for o, a in c.terms),
                                  COUPLING_TOLERANCE * angle * float(
                                      np.sqrt(1.0 + sum(a * a for _, a in c.terms))), c)
                     for c in self.couplings.values())

    def couple(self, angles: np.ndarray) -> np.ndarray:
        """Return the joint angles ``T u + b`` of per-axis angles u, shape (N, n_axes), rad.

        u holds the independent axes' true angles and, on coupled axes, their own angle errors
        (not a readout: a coupled joint has none). Without couplings, u itself.
        """
        if not self.couplings:
            return angles
        out: np.ndarray = angles @ self.coupling_matrix.T + self.coupling_offset
        return out

    def joint_angles(self, corrected: np.ndarray, offsets: np.ndarray | None = None) -> np.ndarray:
        """Return the joint angles (N, n_axes), rad, of corrected readouts and further angle errors.

        Without couplings ``corrected + offsets``; with them, a coupled axis' readout is dropped
        and its angle is its coupling of the others plus its own offset (:meth:`couple`).
        """
        if self.couplings:
            corrected = np.where(self.coupled, 0.0, corrected)
        if offsets is not None:
            corrected = corrected + offsets
        return self.couple(corrected)

    def fill_readouts(self, q: np.ndarray) -> np.ndarray:
        """Return readouts (N, n_axes), rad, with every coupled axis' column set by its coupling."""
        return fill_coupled(q, self.axis_couplings) if self.couplings else q

    # ------------------------------------------------------------------ names
    @property
    def n_axes(self) -> int:
        """Number of encoder axes."""
        return len(self.axis_names)

    @property
    def n_tools(self) -> int:
        """Number of tools (measured points)."""
        return len(self.tool_joints)

    @property
    def tool_names(self) -> list[str]:
        """The tools' names, in tool order: ``<name>`` of ``tool_<name>``, or ``tool``."""
        return [m.group(1) or n for n in self.tool_joints if (m := TOOL_PATTERN.match(n))]

    @property
    def tool_unknowns(self) -> list[str]:
        """Names of the tool vectors' entries, ``<tool joint>_x/_y/_z`` per tool, tool order."""
        return [f"{name}_{c}" for name in self.tool_joints for c in "xyz"]

    def tool_index(self, tool: str | int | np.ndarray | list[str] | list[int]) -> np.ndarray:
        """Return the 0-based tool index of each entry of ``tool`` (names, joint names or indices).

        Raises:
            ValueError: naming an unknown tool and listing the arm's tools.
        """
        arr = np.atleast_1d(np.asarray(tool))
        if arr.dtype.kind in "iu":
            if arr.size and (arr.min() < 0 or arr.max() >= self.n_tools):
                raise ValueError(f"tool: indices 0..{self.n_tools - 1} expected, got "
                                 f"{sorted(set(arr.tolist()))}")
            return arr.astype(np.int64)
        lookup = {**{n: k for k, n in enumerate(self.tool_joints)},
                  **{n: k for k, n in enumerate(self.tool_names)}}
        if bad := sorted({str(v) for v in arr.tolist()} - lookup.keys()):
            raise ValueError(f"tool: unknown tool {', '.join(map(repr, bad))}; the arm's tools: "
                             f"{', '.join(self.tool_names)}")
        return np.array([lookup[str(v)] for v in arr.tolist()], dtype=np.int64)

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
        """Plausible sizes of the arm's errors (:mod:`aacmm_pin.model.sizes`), read once.

        From the sizes file given to :func:`load_arm`, else the one beside the URDF
        (``<name>.sizes.json``); the default AACMM's where there is none.

        Raises:
            FileFormatError: if the sizes file is missing or malformed (naming the file and the
                key).
        """
        return read_sizes(self.sizes_file) if self.sizes_file is not None else DEFAULT_SIZES

    @cached_property
    def joint_limits(self) -> np.ndarray:
        """Lower and upper readout limits of each axis, shape (n_axes, 2), in rad.

        A revolute joint's ``<limit lower upper>``; -pi / pi where the URDF states none (and for
        continuous joints).
        """
        out = np.tile([-np.pi, np.pi], (self.n_axes, 1))
        for i, name in enumerate(self.axis_names):
            joint = self._joints[name]
            if joint.type == "revolute":
                out[i] = [v if v is not None else d
                          for v, d in zip((joint.lower, joint.upper), out[i])]
        return out

    @cached_property
    def stated_limits(self) -> np.ndarray:
        """The limits the URDF states, shape (n_axes, 2), rad (NaN: a continuous joint, no bound).

        Readouts of an axis without a stated bound may lie anywhere (e.g. 0..360 deg). The
        readers warn of readouts beyond them (:func:`aacmm_pin.data.campaign.read_campaign`).
        """
        out = np.full((self.n_axes, 2), np.nan)
        for i, name in enumerate(self.axis_names):
            joint = self._joints[name]
            if joint.type == "revolute":
                out[i] = [np.nan if v is None else v for v in (joint.lower, joint.upper)]
        return out

    # ------------------------------------------------------------------ URDF views
    def urdf_tree(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None,
                  tools: dict[str, np.ndarray] | None = None) -> UrdfTree:
        """Return a copy of the URDF's tree with error frames and tools set to these values.

        Everything else in the file is kept as written (see :mod:`aacmm_pin.model.urdf_tree`).

        Args:
            dh: error frame name -> value (m or rad); missing names keep the URDF's values.
            tool: the first (for a serial arm: the only) tool's vector, shape (3,), in m; None
                keeps the URDF's.
            tools: tool joint name -> tool vector, shape (3,), in m (any tools; over ``tool``).

        Raises:
            FrameNotFound: if ``dh`` or ``tools`` names a parameter the arm does not have.
        """
        dh = dict(dh or {})
        for name in dh:
            if name not in self.error_names:
                raise FrameNotFound(name, self.error_names)
        vectors = {} if tool is None else {self.tool_joints[0]: tool}
        for name, value in (tools or {}).items():
            if name not in self.tool_joints:
                raise FrameNotFound(name, self.tool_joints)
            vectors[name] = value
        tree = self._urdf.copy()
        for name, entry in dh.items():
            frame = self.error_frame(name)
            # a translation's rotation text stays as written
            tree.set_origin(name, frame.transform(float(entry)), keep_rotation=not frame.is_angle)
        for name, vector in vectors.items():
            origin = np.eye(4)
            origin[:3, 3] = np.asarray(vector, dtype=float).reshape(3)
            tree.set_origin(name, origin, keep_rotation=True)
        return tree

    def urdf_string(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None,
                    tools: dict[str, np.ndarray] | None = None) -> str:
        """Return the URDF text with error frames and tools set to these values.

        The rest of the file stays as written: visuals, transmissions, ``<gazebo>``, comments.
        """
        return self.urdf_tree(dh, tool, tools).xml()

    def urdf_robot(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None,
                   tools: dict[str, np.ndarray] | None = None) -> yourdfpy.Robot:
        """Return yourdfpy's description of :meth:`urdf_string` (links, joints, visuals as written).

        Read without a base folder, scene graph or meshes: to load meshes, write the text next to
        them and load it with yourdfpy.

        Raises:
            FrameNotFound: if ``dh`` or ``tools`` names a parameter the arm does not have.
            MissingExtraError: if yourdfpy (the ``urdf`` extra) is not installed.
        """
        import io

        from aacmm_pin.extras import require

        require("urdf", "Arm.urdf_robot")  # yourdfpy, an extra
        import yourdfpy  # its import (trimesh, scipy.spatial) costs ~0.3 s: only here

        text = self.urdf_string(dh, tool, tools).encode()
        urdf = yourdfpy.URDF.load(io.BytesIO(text), build_scene_graph=False, load_meshes=False,
                                  build_collision_scene_graph=False, load_collision_meshes=False)
        return urdf.robot

    def runtime_model(self, dh: dict[str, float] | None = None, tool: np.ndarray | None = None,
                      tools: dict[str, np.ndarray] | None = None) -> pin.Model:
        """Return the runtime Pinocchio model: error frames fixed at these values.

        Its configuration is the n_axes true joint angles in axis order (readouts already corrected
        by the encoder maps, see :func:`aacmm_pin.model.encoder_map.correct_readouts`); the frames
        ``tool_links`` are the tool points. Movable joints on no tool's chain are fixed at zero.
        A coupled joint stays free here: its entry is its angle, :meth:`joint_angles` of the
        corrected readouts.
        """
        tree = self.urdf_tree(dh, tool, tools)
        for name in self.off_chain:
            tree.make_fixed(name)
        return build_model(tree)

    @cached_property
    def nominal_model(self) -> pin.Model:
        """The runtime model at the URDF's own values (:meth:`runtime_model`), built once.

        Shared, read only (e.g. the gravity torques of :class:`~aacmm_pin.model.samples.Samples`).
        """
        return self.runtime_model()

    @cached_property
    def identification(self) -> IdentificationModel:
        """The identification model (built once)."""
        return IdentificationModel(self)


class IdentificationModel:
    """Pinocchio model in which every parameter is a 1-DOF joint along its own axis.

    Joint order (root first): the r-CS -> MT-CS translation ``mt_x, mt_y, mt_z`` and rotation
    ``beta0, alpha0, gamma0`` (Eq. 4), then the arm's tree with axes and error frames, then each
    tool's vector (``tool_x, tool_y, tool_z``; ``tool_left_x`` ...). Every joint has one
    configuration entry, so ``nq == nv``.
    """

    def __init__(self, arm: Arm):
        tree = arm._urdf.copy()
        for frame in arm.error_frames:
            tree.make_one_dof(frame.name, "revolute" if frame.is_angle else "prismatic", frame.axis,
                              zero_origin=True)
        for name in arm.axis_names:
            tree.make_one_dof(name, "revolute", arm._joints[name].axis, zero_origin=False)
        for name in arm.off_chain:
            tree.make_fixed(name)
        for tool_name in arm.tool_joints:
            tool = arm._joints[tool_name]
            tree.remove_joint(tool_name)
            parent = tool.parent
            for i, c in enumerate("xyz"):
                name = f"{tool_name}_{c}"
                child = tool.child if i == 2 else f"{name}_frame"
                if i < 2:
                    tree.add_link(child)
                tree.add_joint(name, "prismatic", parent, child, np.eye(3)[i])
                parent = child
        parent = "mt"
        tree.add_link("mt")
        for i, name in enumerate(BASE_JOINTS):
            child = arm.root_link if i == 5 else f"{name}_frame"
            if i < 5:
                tree.add_link(child)
            tree.add_joint(name, "prismatic" if i < 3 else "revolute", parent, child,
                           np.eye(3)[[0, 1, 2, 1, 0, 2][i]])
            parent = child
        self.model: pin.Model = build_model(tree)
        """The Pinocchio model."""
        self._local = threading.local()
        self.tool_frames: list[int] = [self.model.getFrameId(link) for link in arm.tool_links]
        """Pinocchio frame ids of the tool points, in tool order."""
        self.stylus_frame: int = self.tool_frames[0]
        """Pinocchio frame id of the (first) stylus sphere centre."""
        idx = {name: self.model.joints[self.model.getJointId(name)].idx_q
               for name in self.model.names[1:]}
        self.base_idx: np.ndarray = np.array([idx[n] for n in BASE_JOINTS])
        """Configuration indices of (mt_x, mt_y, mt_z, beta0, alpha0, gamma0)."""
        self.axis_idx: np.ndarray = np.array([idx[n] for n in arm.axis_names])
        """Configuration indices of the axes A1..An."""
        self.error_idx: np.ndarray = np.array([idx[n] for n in arm.error_names], dtype=int)
        """Configuration indices of the error frames, in ``arm.error_names`` order."""
        self.tool_idx: np.ndarray = np.array([idx[n] for n in arm.tool_unknowns])
        """Configuration indices of the tool vectors (x, y, z per tool, tool order)."""
        assert self.model.nq == self.model.nv == len(idx)
        self.chain: BatchedChain = BatchedChain(self.model)
        """The model's kinematics vectorised over samples (positions and frame Jacobians)."""

    @property
    def data(self) -> pin.Data:
        """The model's workspace, one per thread (Pinocchio's Data is not shared safely)."""
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        return data


def load_arm(arm: str | Path = DEFAULT_ARM, tool_frame: str | None = None,
             sizes: str | Path | None = None, *, error_frames: bool = True) -> Arm:
    """Load an arm from a URDF path or an embedded arm's name (default: ``aacmm7``).

    A robot's own URDF is completed in memory (:mod:`aacmm_pin.model.urdf_completion`): without a
    ``tool`` joint, one is added on the link ``tool_frame`` (default ``tool0``); without error
    frames, six are added before each axis. :attr:`Arm.note` says what was added.

    Args:
        arm: URDF path or embedded arm name.
        tool_frame: the link the measured point hangs off, for a URDF without a ``tool`` joint;
            None: ``tool0``.
        sizes: the arm's sizes file (:mod:`aacmm_pin.model.sizes`) or an embedded arm's name (its
            sizes file, :func:`~aacmm_pin.model.arm_files.resolve_sizes_path`); None: the one
            beside the URDF (``<urdf>.sizes.json``), else the defaults.
        error_frames: add error frames to a URDF that has none; False loads a calibrated arm whose
            values are folded into its joint origins (a calibration folder's ``compact.urdf``)
            as it is.

    Raises:
        ArmModelError: if the file cannot be read, breaks the conventions or gives nothing to
            calibrate (message names the file, and the line and column for XML syntax errors), or
            if ``sizes`` is neither a file nor an embedded arm with a sizes file.
    """
    path = resolve_arm_path(arm)
    sizes = resolve_sizes_path(sizes) if sizes is not None else None
    urdf, frame = add_tool_joint(read_urdf(path), tool_frame)
    out = Arm(urdf, path, str(arm), sizes=sizes, completion=Completion(frame))
    if not out.error_frames and error_frames:
        urdf, added = add_error_frames(urdf, out.axis_names)
        out = Arm(urdf, path, str(arm), sizes=sizes,
                  completion=Completion(frame, added, tuple(out.axis_names)))
    return out


_LOADED: dict[tuple[str, str, str | None, str | None, bool, str], Arm] = {}


def _load_named(path: str, name: str, tool_frame: str | None = None,
                sizes: str | None = None, error_frames: bool = True) -> Arm:
    """Load (once per process) the arm of a URDF path and keep the user's name for it."""
    file = Path(sizes) if sizes is not None else sizes_file(path)
    # an edited URDF or sizes file reloads
    data = Path(path).read_bytes() + (file.read_bytes() if file is not None and file.is_file()
                                      else b"")
    key = (path, name, tool_frame, sizes, error_frames, hashlib.sha1(data).hexdigest())
    if key not in _LOADED:
        arm = load_arm(path, tool_frame, sizes, error_frames=error_frames)
        arm.name = name
        _LOADED[key] = arm
    return _LOADED[key]
