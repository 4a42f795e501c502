r"""Batch kinematics: stylus centres and their Jacobians for N readouts at once.

Positions and Jacobians are those of Pinocchio's models: forward kinematics and the frame Jacobian
(``LOCAL_WORLD_ALIGNED``) of the identification model (:class:`aacmm_pin.model.arm.IdentificationModel`),
in which every parameter is a joint, so every column is analytic. They are evaluated for all samples
at once (:class:`aacmm_pin.model._chain.BatchedChain`: the joint placements and axes come from the
Pinocchio model, the products along the chain are vectorised over samples with numpy; the tests
check them against Pinocchio's per-sample functions). Map nodes enter through the chain rule:
:math:`\partial p / \partial \Delta\theta_{n,map}(k) = \partial p / \partial \theta_n \cdot w_k(\theta^*_n)`
with the interpolation weights :math:`w_k` of :meth:`EncoderMap.weights`.

Extension terms change the arm through an :class:`Adjustment`: angle offsets, a length scale,
lateral tilts of joints and small twists of any frame (everything hanging from a moved frame
moves with it; :meth:`StylusJacobians.twist` gives the point's columns of a frame's twist).

Inverse kinematics (:func:`solve_ik`, the simulator's postures, the planner's candidates) needs
only the n_axes joint columns: :class:`JointKinematics` computes them on the runtime model, not the
identification model's DH, tool and map columns.

Coupled joints (:meth:`Arm.couple`): the joint angles are :math:`T u + b` of per-axis angles u (the
independent axes' corrected readouts and angle errors, the coupled axes' own angle errors; a
coupled axis' readout column is not read), so the ``angles`` columns are the chain rule
:math:`J_\theta T` and a coupled axis has no ``readouts`` column (zero).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, TypeAlias

import numpy as np
import pinocchio as pin

from aacmm_pin.errors import AacmmError, FrameNotFound
from aacmm_pin.model._chain import BatchedChain
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.encoder_map import correct_readouts, correct_with_slopes
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples

if TYPE_CHECKING:  # sparse matrices are made where an identification asks for them
    import scipy.sparse as sp


class StylusJacobians(NamedTuple):
    """Stylus centres and their derivatives for N samples (frame chosen by the caller)."""

    position: np.ndarray
    """Stylus centres, shape (N, 3), in m."""
    readouts: np.ndarray
    """d(position)/d(encoder readout), shape (N, 3, n_axes), in m/rad (map slopes included)."""
    angles: np.ndarray
    """d(position)/d(true joint angle), shape (N, 3, n_axes), in m/rad."""
    dh: np.ndarray
    """d(position)/d(error frame value), shape (N, 3, n_errors), in m/m or m/rad."""
    tool: np.ndarray
    """d(position)/d(tool vectors), shape (N, 3, 3 n_tools), dimensionless (zero for the tools a
    sample does not measure)."""
    rotation: np.ndarray
    """d(position)/d(alpha0, beta0, gamma0), shape (N, 3, 3), in m/rad (zero-sized use in r-CS)."""
    translation: np.ndarray
    """d(position)/d(translation), shape (N, 3, 3), dimensionless."""
    q_readout: np.ndarray
    """The readouts used, shape (N, n_axes), in rad (for :meth:`nodes`)."""
    tilts: np.ndarray | None = None
    """d(position)/d(lateral tilt of each axis about its two lateral axes), shape
    (N, 3, n_axes, 2), in m/rad, when asked for (``stylus_jacobians(..., tilts=True)``)."""
    frame_columns: Callable[[str], np.ndarray] | None = None
    """Frame name -> d(position)/d(a small twist of that frame), computed when first asked for
    (:meth:`twist`)."""

    def twist(self, frame: str) -> np.ndarray:
        """Return d(position)/d(a small twist of a frame in its own axes), shape (N, 3, 6).

        Columns in m/m (the linear part, first) and m/rad (the angular part), zero for the
        samples whose tool does not hang from the frame (see
        :meth:`~aacmm_pin.model._chain.BatchedChain.twist_columns`).

        Raises:
            FrameNotFound: if the model has no frame of that name (naming the frames it has).
        """
        if self.frame_columns is None:
            raise ValueError("these stylus Jacobians hold no frame columns")
        return self.frame_columns(frame)

    def nodes(self, params: Parameters, axis: int) -> sp.csr_matrix:
        """Return d(position)/d(map nodes of one axis), sparse, shape (3N, n_nodes), m/rad.

        Rows are ordered sample-major: row ``3 * i + k`` is coordinate k of sample i.
        """
        import scipy.sparse as sp

        return sp.csr_matrix(params.map(axis).node_columns(self.q_readout[:, axis - 1],
                                                           self.angles[:, :, axis - 1]))


def _readouts_2d(readouts: np.ndarray, arm: Arm) -> np.ndarray:
    q = np.atleast_2d(np.asarray(readouts, dtype=float))
    if q.ndim != 2 or q.shape[1] != arm.n_axes:
        raise ValueError(f"readouts: need shape (N, {arm.n_axes}) in rad, got {np.shape(readouts)}")
    return q


ToolIndex: TypeAlias = "str | int | np.ndarray | list[str] | list[int] | None"
"""Which tool each sample measures: one name / index for all, or one per sample; None: the
samples' own (:attr:`Samples.tool`), else the arm's only tool."""


def tool_rows(arm: Arm, n: int, tool: ToolIndex = None, samples: Samples | None = None
              ) -> np.ndarray:
    """Return the 0-based tool index of each of n samples, shape (n,).

    Args:
        arm: the arm.
        n: number of samples.
        tool: see :data:`ToolIndex`.
        samples: the samples, whose ``tool`` is used when ``tool`` is None.

    Raises:
        ValueError: for an unknown tool, a length other than n, or no tool given for an arm with
            several tools.
    """
    if tool is None and samples is not None and samples.tool is not None and samples.n == n:
        return samples.tool
    if tool is None:
        if arm.n_tools > 1:
            raise ValueError(f"tool: the arm has {arm.n_tools} tools ({', '.join(arm.tool_names)}); "
                             "say which one each sample measures")
        return np.zeros(n, dtype=np.int64)
    idx = arm.tool_index(tool)
    if idx.size == 1:
        return np.full(n, idx[0], dtype=np.int64)
    if idx.size != n:
        raise ValueError(f"tool: one tool or one per sample ({n}) expected, got {idx.size}")
    return idx


def _tool_values(arm: Arm, params: Parameters) -> np.ndarray:
    """Return the tool vectors of the identification model's tool joints, shape (3 n_tools,)."""
    return np.concatenate(list(params.tool_vectors(arm).values()))


@dataclass
class Adjustment:
    """How a calibration's extension terms change the arm at N samples (SI).

    Built by the effect library (:func:`aacmm_pin.effects.forward.adjustment`) and applied here.

    Args:
        n: number of samples.
        n_axes: number of axes.
    """

    n: int
    n_axes: int
    offsets: np.ndarray = field(init=False)
    """Angle errors added to the true joint angles, shape (N, n_axes), rad."""
    scale: np.ndarray = field(init=False)
    """Scale of every length of the arm about the r-CS origin, shape (N,)."""
    tilts: np.ndarray = field(init=False)
    """Lateral tilt of each joint about its two lateral axes, shape (N, n_axes, 2), rad."""
    twists: dict[str, np.ndarray] = field(init=False)
    """Frame name -> its small twist (linear, then angular) in its own axes, shape (N, 6), m and
    rad: everything hanging from the frame moves with it (:meth:`twist`)."""

    def __post_init__(self) -> None:
        self.offsets = np.zeros((self.n, self.n_axes))
        self.scale = np.ones(self.n)
        self.tilts = np.zeros((self.n, self.n_axes, 2))
        self.twists = {}

    def twist(self, frame: str) -> np.ndarray:
        """Return the twist of a frame of the arm's Pinocchio model, shape (N, 6), to add to."""
        if frame not in self.twists:
            self.twists[frame] = np.zeros((self.n, 6))
        return self.twists[frame]

    @property
    def tilted(self) -> bool:
        """Whether any joint is tilted."""
        return bool(np.any(self.tilts != 0.0))

    @property
    def moves_frames(self) -> bool:
        """Whether any frame moves by a twist."""
        return any(np.any(t != 0.0) for t in self.twists.values())

    @property
    def moves_point(self) -> bool:
        """Whether tilts or twists move the point beyond the joint angles and the scale."""
        return self.tilted or self.moves_frames


def _tilt_shift(chain: BatchedChain, q: np.ndarray, frames: np.ndarray, axes: np.ndarray,
                tilts: np.ndarray) -> np.ndarray:
    """Return the move of the frames' points by small lateral tilts of the axes, shape (N, 3), m.

    First order in the tilts (N, n_axes, 2), rad: the sum over the axes and their two lateral
    directions of the tilt times its column (:meth:`BatchedChain.tilt_columns`).
    """
    shift: np.ndarray = np.einsum("nijk,njk->ni", chain.tilt_columns(q, frames, axes), tilts)
    return shift


def frame_ids(arm: Arm, model: pin.Model, names: Iterable[str]) -> np.ndarray:
    """Return the Pinocchio frame ids in ``model`` of frames of the arm named in its URDF, (M,).

    The names are those of the arm's URDF (:attr:`Arm.nominal_model`'s frames: links, joints,
    error frames, the tool joints), the same for the identification model (where a tool joint's
    frame is its tool link's, the same placement) and the runtime one.

    Raises:
        FrameNotFound: naming the first name that is no frame of the URDF (or of ``model``), and
            the URDF's links and joints.
    """
    urdf = arm.nominal_model
    ids = []
    for name in names:
        known = name != "universe" and urdf.existFrame(name)
        if known and name in arm.tool_joints and not model.existFrame(name):
            name = arm.tool_links[arm.tool_joints.index(name)]
        if not known or not model.existFrame(name):
            raise FrameNotFound(name, [f.name for f in urdf.frames if f.name != "universe"
                                       and not f.name.endswith("_frame")])
        ids.append(model.getFrameId(name))
    return np.array(ids, dtype=np.int64)


def _twist_shift(chain: BatchedChain, arm: Arm, model: pin.Model, q: np.ndarray, frames: np.ndarray,
                 twists: dict[str, np.ndarray]) -> np.ndarray:
    """Return the move of the frames' points by small twists of other frames, shape (N, 3), m.

    First order in the twists (frame name -> (N, 6), m and rad, in the frame's own axes): the
    sum of each twist times its columns (:meth:`BatchedChain.twist_columns`).
    """
    names = [name for name, t in twists.items() if np.any(t != 0.0)]
    cols = chain.twist_columns(q, frames, frame_ids(arm, model, names))
    shift: np.ndarray = np.einsum("nimk,nmk->ni", cols, np.stack([twists[n] for n in names], axis=1))
    return shift


def _frame_columns(chain: BatchedChain, arm: Arm, model: pin.Model, q: np.ndarray, frames: np.ndarray,
                   scale: np.ndarray) -> Callable[[str], np.ndarray]:
    """Return frame name -> d(points)/d(its twist), (N, 3, 6), computed once per frame."""
    done: dict[str, np.ndarray] = {}

    def columns(name: str) -> np.ndarray:
        if name not in done:
            cols = chain.twist_columns(q, frames, frame_ids(arm, model, [name]))[:, :, 0, :]
            done[name] = cols * scale[:, None, None]
        return done[name]

    return columns


def _adjusted(adjust: Adjustment | None, q_read: np.ndarray) -> Adjustment:
    return adjust if adjust is not None else Adjustment(*q_read.shape)


def _matching(samples: Samples | None, q: np.ndarray) -> Samples | None:
    """Return the samples if they describe readouts q, else None."""
    return samples if samples is not None and samples.matches(q) else None


def _scaled(pos: np.ndarray, scale: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Return positions scaled about the r-CS origin (at ``origin`` in the output frame)."""
    scaled: np.ndarray = origin + scale[:, None] * (pos - origin)
    return scaled


def _coupled_columns(arm: Arm, angles: np.ndarray) -> np.ndarray:
    """Return d(position)/d(per-axis angles u) from d(position)/d(joint angles), (N, 3, n_axes)."""
    if not arm.couplings:
        return angles
    out: np.ndarray = angles @ arm.coupling_matrix
    return out


def identification_configuration(arm: Arm, params: Parameters, readouts: np.ndarray,
                                 frame: str = "mt", offsets: np.ndarray | None = None
                                 ) -> np.ndarray:
    """Return the identification model's configurations, shape (N, nq).

    Args:
        arm: the arm.
        params: DH values, tool, X0, translation and maps.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"mt"`` to include the r-CS -> MT-CS transform, ``"r"`` for the r-CS.
        offsets: further angle errors (extensions), shape (N, n_axes), rad.
    """
    if frame not in ("r", "mt"):
        raise ValueError(f"frame: choose 'r' or 'mt', got {frame!r}")
    ident = arm.identification
    q_read = _readouts_2d(readouts, arm)
    q = np.zeros((q_read.shape[0], ident.model.nq))
    if frame == "mt":
        alpha, beta, gamma = params.rotation_abc
        q[:, ident.base_idx] = [*params.translation, beta, alpha, gamma]
    if arm.couplings:
        q[:, ident.axis_idx] = arm.joint_angles(correct_readouts(q_read, params.encoder_maps),
                                            offsets)
    else:
        q[:, ident.axis_idx] = correct_readouts(q_read, params.encoder_maps)
        if offsets is not None:
            q[:, ident.axis_idx] += offsets
    q[:, ident.error_idx] = [params.dh.get(n, f.nominal) for n, f in
                             zip(arm.error_names, arm.error_frames)]
    q[:, ident.tool_idx] = _tool_values(arm, params)
    return q


def stylus_positions(arm: Arm, params: Parameters, readouts: np.ndarray, frame: str = "r",
                     samples: Samples | None = None, *, tool: ToolIndex = None,
                     adjust: Adjustment | None = None) -> np.ndarray:
    """Return stylus sphere centres for N readouts, shape (N, 3), in m.

    Args:
        arm: the arm.
        params: calibrated parameters (maps, DH values, tool, X0 for the MT-CS, extensions).
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"r"`` (r-CS, the arm's own frame) or ``"mt"`` (the R-Test's MT-CS).
        samples: temperature and motion of the samples, for extensions that need them.
        tool: which tool each sample measures (see :data:`ToolIndex`).
        adjust: the extension terms' change of the arm at these readouts (default: none; the
            effect library's :func:`aacmm_pin.stylus_positions` computes it from ``params``).
    """
    ident = arm.identification
    q_read = _readouts_2d(readouts, arm)
    fids = np.asarray(ident.tool_frames)[tool_rows(arm, len(q_read), tool, _matching(samples, q_read))]
    if adjust is None and len(q_read) > POSITIONS_CHUNK:  # the chain alone: chunk by chunk
        return _chunked_positions(arm, params, q_read, frame, fids)
    change = _adjusted(adjust, q_read)
    q = identification_configuration(arm, params, q_read, frame, change.offsets)
    out = ident.chain.positions(q, fids)
    if change.tilted:
        out = out + _tilt_shift(ident.chain, q, fids, ident.axis_idx, change.tilts)
    if change.moves_frames:
        out = out + _twist_shift(ident.chain, arm, ident.model, q, fids, change.twists)
    if adjust is not None:
        out = _scaled(out, change.scale, params.translation if frame == "mt" else np.zeros(3))
    return out


POSITIONS_CHUNK = 65536
"""Samples per block of :func:`stylus_positions` without extensions (a multiple of the chain's
own block, :data:`~aacmm_pin.model._chain.CHUNK`, so that every sample's arithmetic is that of
one call): the configurations (8 ``nq`` bytes per sample, 0.5 GB at 1.6M samples of the paper's
arm) exist for one block only."""


def _chunked_positions(arm: Arm, params: Parameters, q_read: np.ndarray, frame: str,
                       fids: np.ndarray) -> np.ndarray:
    """Return :func:`stylus_positions` without extensions, block by block, shape (N, 3), m.

    :data:`POSITIONS_CHUNK` samples at a time; ``q_read`` (N, n_axes) rad, ``fids`` the tool
    frame of every sample, shape (N,).
    """
    out = np.empty((len(q_read), 3))
    for lo in range(0, len(q_read), POSITIONS_CHUNK):
        hi = min(len(q_read), lo + POSITIONS_CHUNK)
        config = identification_configuration(arm, params, q_read[lo:hi], frame)
        out[lo:hi] = arm.identification.chain.positions(config, fids[lo:hi])
    return out


def stylus_jacobians(arm: Arm, params: Parameters, readouts: np.ndarray, frame: str = "r",
                     samples: Samples | None = None, *, tool: ToolIndex = None,
                     adjust: Adjustment | None = None, tilts: bool = False) -> StylusJacobians:
    """Return stylus centres and their analytic Jacobians for N readouts.

    Args:
        arm: the arm.
        params: parameters at which to linearise.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"r"`` (the arm's own frame, the r-CS; the default, as everywhere) or ``"mt"``
            (the instrument's MT-CS, with X0 and translation).
        samples: temperature and motion of the samples, for extensions that need them.
        tool: which tool each sample measures (see :data:`ToolIndex`); each sample's Jacobian is
            that of its own tool's frame.
        adjust: the extension terms' change of the arm (see :func:`stylus_positions`).
        tilts: also the columns of each joint's lateral tilts (:attr:`StylusJacobians.tilts`).
    """
    ident = arm.identification
    q_read = _readouts_2d(readouts, arm)
    fids = np.asarray(ident.tool_frames)[tool_rows(arm, len(q_read), tool, _matching(samples, q_read))]
    change = _adjusted(adjust, q_read)
    scale = change.scale
    q = identification_configuration(arm, params, q_read, frame, change.offsets)
    # one array, its column blocks in field order: rotation, translation, angles, dh, tool (views)
    order = [ident.base_idx[[4, 3, 5]], ident.base_idx[:3], ident.axis_idx, ident.error_idx,
             ident.tool_idx]
    ends = np.cumsum([0] + [len(o) for o in order])
    pos, jac = ident.chain.jacobians(q, fids, np.concatenate(order))
    tilt_cols = ident.chain.tilt_columns(q, fids, ident.axis_idx) if (
        tilts or change.tilted) else None
    if change.tilted:
        assert tilt_cols is not None
        pos = pos + np.einsum("nijk,njk->ni", tilt_cols, change.tilts)
    if change.moves_frames:
        pos = pos + _twist_shift(ident.chain, arm, ident.model, q, fids, change.twists)
    if adjust is not None:  # every length scaled about the r-CS origin: all but the translation
        origin = params.translation if frame == "mt" else np.zeros(3)
        pos = _scaled(pos, scale, origin)
        jac *= scale[:, None, None]
        jac[:, :, ends[1]:ends[2]] /= scale[:, None, None]
    rotation, translation, angles, dh, tools = (jac[:, :, a:b] for a, b in zip(ends, ends[1:]))
    angles = _coupled_columns(arm, angles)
    slope = np.ones_like(q_read)
    for axis in params.encoder_maps:
        slope[:, axis - 1] += params.encoder_maps[axis].slope(q_read[:, axis - 1])
    slope[:, arm.coupled] = 0.0  # no readout
    return StylusJacobians(
        position=pos,
        readouts=angles * slope[:, None, :],
        angles=angles,
        dh=dh,
        tool=tools,
        rotation=rotation,
        translation=translation,
        q_readout=q_read,
        tilts=None if tilt_cols is None else tilt_cols * scale[:, None, None, None],
        frame_columns=_frame_columns(ident.chain, arm, ident.model, q, fids, scale),
    )


def predict(arm: Arm, params: Parameters, readouts: np.ndarray, samples: Samples | None = None,
            *, tool: ToolIndex = None, adjust: Adjustment | None = None) -> np.ndarray:
    """Return stylus centres in the r-CS for N readouts with the *runtime* model, shape (N, 3), m.

    This is what a robotics stack does with a calibrated arm: wrap the readouts with the encoder
    maps (and the angle terms of the extensions), then run forward kinematics of the URDF whose
    error frames hold the calibrated values (and scale by a thermal term, if any).

    Args:
        arm: the nominal arm.
        params: calibrated parameters.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        samples: temperature and motion of the samples, for extensions that need them.
        tool: which tool each sample measures (see :data:`ToolIndex`).
        adjust: the extension terms' change of the arm (see :func:`stylus_positions`).
    """
    return JointKinematics(arm, params).positions(readouts, tool, adjust, samples)


class JointKinematics:
    """Stylus centres and their joint Jacobian only (n_axes columns), for inverse kinematics.

    The runtime model of one set of parameters (:meth:`Arm.runtime_model`: error frames and tool
    vectors fixed at their values) evaluated for N readouts at once
    (:class:`~aacmm_pin.model._chain.BatchedChain`); no DH, tool or map columns are formed. The
    positions are the model's (:func:`stylus_positions` in the r-CS) to rounding.

    Args:
        arm: the arm.
        params: the parameters (DH values, tool vectors, encoder maps; X0 is not used: r-CS).
    """

    def __init__(self, arm: Arm, params: Parameters):
        model = arm.runtime_model(params.dh, tools=params.tool_vectors(arm))
        self.arm, self.params = arm, params
        self.model: pin.Model = model
        """The runtime model (:meth:`Arm.runtime_model` of the parameters)."""
        self.chain = BatchedChain(model)
        self.frames = np.array([model.getFrameId(link) for link in arm.tool_links])
        self.axes = np.array([model.joints[model.getJointId(n)].idx_q for n in arm.axis_names])

    def positions(self, readouts: np.ndarray, tool: ToolIndex = None,
                  adjust: Adjustment | None = None, samples: Samples | None = None) -> np.ndarray:
        """Return r-CS stylus centres for N readouts with the runtime model, shape (N, 3), m.

        :func:`predict` on this model: the readouts wrapped by the encoder maps (and the angle
        terms of ``adjust``), forward kinematics, lateral tilts and scale.

        Args:
            readouts: encoder readouts, shape (N, n_axes), in rad.
            tool: which tool each sample measures (see :data:`ToolIndex`).
            adjust: the extension terms' change of the arm (see :func:`stylus_positions`).
            samples: the samples, whose ``tool`` is used when ``tool`` is None.
        """
        q_read = _readouts_2d(readouts, self.arm)
        fids = self.frames[tool_rows(self.arm, len(q_read), tool, _matching(samples, q_read))]
        change = _adjusted(adjust, q_read)
        q = np.zeros((len(q_read), self.chain.nq))
        q[:, self.axes] = self.arm.joint_angles(correct_readouts(q_read, self.params.encoder_maps),
                                                change.offsets)
        positions: np.ndarray = self.chain.positions(q, fids)
        if change.tilted:
            positions = positions + _tilt_shift(self.chain, q, fids, self.axes, change.tilts)
        if change.moves_frames:
            positions = positions + _twist_shift(self.chain, self.arm, self.model, q, fids, change.twists)
        scaled: np.ndarray = positions * change.scale[:, None]
        return scaled

    def position_jacobian(self, readouts: np.ndarray, tool: ToolIndex = None,
                          adjust: Adjustment | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return r-CS stylus centres (N, 3), m, and d(centre)/d(readouts) (N, 3, n_axes), m/rad.

        Args:
            readouts: encoder readouts, shape (N, n_axes), in rad.
            tool: which tool each sample measures (see :data:`ToolIndex`).
            adjust: the extension terms' change of the arm (angle offsets, lateral tilts, frame
                twists and scale enter the positions; the Jacobian holds the offsets and the scale, as
                :func:`stylus_jacobians` does).
        """
        q_read = _readouts_2d(readouts, self.arm)
        fids = self.frames[tool_rows(self.arm, len(q_read), tool)]
        change = _adjusted(adjust, q_read)
        q = np.zeros((len(q_read), self.chain.nq))
        angles, slope = correct_with_slopes(q_read, self.params.encoder_maps)
        q[:, self.axes] = self.arm.joint_angles(angles, change.offsets)
        pos, jac = self.chain.joint_jacobians(q, fids, self.axes)
        jac = _coupled_columns(self.arm, jac)
        slope[:, self.arm.coupled] = 0.0  # a coupled axis has no readout: no column
        if change.tilted:
            pos = pos + _tilt_shift(self.chain, q, fids, self.axes, change.tilts)
        if change.moves_frames:
            pos = pos + _twist_shift(self.chain, self.arm, self.model, q, fids, change.twists)
        if adjust is not None:
            pos = pos * change.scale[:, None]
            jac = jac * change.scale[:, None, None]
        return pos, jac * slope[:, None, :]


PositionJacobian = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``(q, rows) -> (positions (M, 3), d(positions)/d(q) (M, 3, n_axes))`` for readouts q (M, n_axes)
of the targets ``rows`` (M,) (so that per-target inputs such as temperature can be selected)."""


def solve_ik(position_jacobian: PositionJacobian, targets: np.ndarray, limits: np.ndarray,
             rng: np.random.Generator, iterations: int = 25, starts: np.ndarray | None = None,
             q_init: np.ndarray | None = None) -> np.ndarray:
    """Return readouts (N, n_axes) putting the modelled point on each target (N, 3).

    Random starts within the joint limits (or within ``starts``, to favour a posture family),
    damped Newton steps projected on the limits, and restarts for the targets not reached to
    1e-12 m.

    Args:
        position_jacobian: the model's positions and their Jacobian (see :data:`PositionJacobian`).
        targets: target points in the model's frame, shape (N, 3), m.
        limits: joint limits, shape (n_axes, 2), rad.
        rng: random generator of the starts.
        iterations: most Newton steps per start.
        starts: box of the random starts, shape (n_axes, 2), rad (clipped to the limits).
        q_init: readouts for the first start, shape (N, n_axes), rad.

    Raises:
        AacmmError: if some target is not reached from 100 starts.
    """
    box = limits if starts is None else np.clip(starts, limits[:, :1], limits[:, 1:])
    n_axes = limits.shape[0]
    q = np.empty((targets.shape[0], n_axes))
    todo = np.arange(targets.shape[0])
    damping = 1e-8 * np.eye(3)
    for attempt in range(100):
        qs = rng.uniform(box[:, 0], box[:, 1], size=(todo.size, n_axes))
        if attempt == 0 and q_init is not None:
            qs = q_init.copy()
        active = np.arange(todo.size)
        for _ in range(iterations):
            sel = todo[active]
            pos, jac = position_jacobian(qs[active], sel)
            err = targets[sel] - pos
            moving = np.linalg.norm(err, axis=1) > 1e-12
            active, err, jac = active[moving], err[moving], jac[moving]
            if active.size == 0:
                break
            jjt = jac @ jac.transpose(0, 2, 1) + damping
            step = (jac.transpose(0, 2, 1) @ np.linalg.solve(jjt, err[:, :, None]))[:, :, 0]
            scale = np.minimum(1.0, 0.5 / np.maximum(np.abs(step).max(axis=1), 1e-300))
            qs[active] = np.clip(qs[active] + scale[:, None] * step, limits[:, 0], limits[:, 1])
        ok = np.ones(todo.size, dtype=bool)
        ok[active] = False
        q[todo[ok]] = qs[ok]
        todo = todo[~ok]
        if todo.size == 0:
            return q
    raise AacmmError(f"IK found no posture within the joint limits for {todo.size} targets, "
                     f"e.g. {targets[todo[0]].round(4).tolist()} m")
