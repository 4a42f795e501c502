r"""A calibrated arm at run time: readouts in, true joint angles, tool placements and Jacobians out.

What a robotics stack holds after loading a calibration once
(:func:`~aacmm_pin.effects.calibrated_folder.load_calibrated`): one
Pinocchio model of the calibrated arm and its data, the encoder maps and the extension terms, and
every function a control loop or a batch job calls on them:

* :meth:`CalibratedArm.true_angles`: encoder readouts -> the true joint angles (maps, couplings,
  the extension terms' angle errors), which the arm's Pinocchio model (:attr:`CalibratedArm.model`,
  or the folder's ``compact.urdf``) takes as its configuration;
* :meth:`CalibratedArm.readouts`: the inverse, true joint angles -> the readouts to command (after
  an inverse kinematics on :attr:`CalibratedArm.model`, say);
* :meth:`CalibratedArm.position`, :meth:`CalibratedArm.placement`: the tool's point and its full
  placement, exactly :func:`aacmm_pin.predict`;
* :meth:`CalibratedArm.jacobian`: the tool frame's Jacobian with respect to the readouts.

**One frame convention.** Every result is in the arm's own frame (the r-CS: the URDF's root link)
unless ``frame="mt"`` asks for the instrument's frame (the R-Test's MT-CS, or a tracker's frame:
the calibration's ``base_to_mt``, paper Eq. 4).

**Shapes.** A readout vector of shape (n_axes,) is one sample and gives one result (position (3,),
placement (4, 4), Jacobian (6, n_axes)); an array (N, n_axes) is N samples and gives N results
stacked on a leading axis. Angles in rad, lengths in m.

**Checks.** Every public method refuses, in one line naming the argument, a wrong number of axes,
a value that is not finite, and readouts beyond an axis' limits by more than half a turn (e.g.
degrees given for radians): :class:`~aacmm_pin.errors.ArgumentError`.

**Cost.** One sample without extension terms runs in plain Python floats and one Pinocchio forward
kinematics call (about 15 us, 6x Pinocchio's own, ``benchmarks/runtime.py``); batches run vectorised
(:class:`~aacmm_pin.model.kinematics.JointKinematics`). Extension terms (gravity compliance,
backlash, temperature, ...) are evaluated through the effect library on every call: slower, and
some need per-sample inputs (``columns``: ``temp_c`` and the like; ``direction``: the direction each
axis last moved in, for backlash; a batch's row order stands for time order when not given).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pinocchio as pin

from aacmm_pin.effects._plain_maps import PlainMaps
from aacmm_pin.effects.forward import term_values, terms_adjustment
from aacmm_pin.effects.parameters_file import check_extensions
from aacmm_pin.errors import ArgumentError
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.encoder_map import correct_with_slopes, readouts_of_angles
from aacmm_pin.model.kinematics import Adjustment, JointKinematics, tool_rows
from aacmm_pin.model.parameters import Parameters, check_against_arm
from aacmm_pin.model.samples import Samples

__all__ = ["CalibratedArm"]

DEGREE_MARGIN = math.pi
"""How far beyond an axis' limits (rad) a readout may lie before it is refused as degrees given for
radians: half a turn (a readout of a table that wraps may pass a limit by less)."""
UNLIMITED_TURNS = 2
"""An axis whose URDF states no limits (a continuous joint) takes readouts within this many turns
either way of zero; beyond, they are refused as degrees given for radians."""
ANGLE_SLACK = 0.01
"""True angles (:meth:`CalibratedArm.readouts`) may pass the readouts' bounds by the maps' largest
value and this much more, rad (the extension terms' angle errors: a few arcminutes at most)."""
INVERSE_TOLERANCE = 1e-13
"""The fixed-point iteration of :meth:`CalibratedArm.readouts` with extension terms stops when no
readout moves by more than this, rad."""
_INVERSE_ITERATIONS = 50
_WORLD = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class CalibratedArm:
    """A calibrated arm, loaded once: its Pinocchio model and data, maps and extension terms.

    Args:
        arm: the arm (its URDF: error frames or compact, see :func:`load_calibrated`).
        params: its calibrated parameters.

    Raises:
        FileFormatError: if the parameters do not fit the arm (error frames, tools, axes, terms).
    """

    def __init__(self, arm: Arm, params: Parameters):
        check_against_arm(params, arm)
        check_extensions(params, arm)
        self.arm: Arm = arm
        """The arm."""
        self.parameters: Parameters = params
        """The calibrated parameters (SI)."""
        self._joints = JointKinematics(arm, params)
        self.model: pin.Model = self._joints.model
        """The Pinocchio model of the calibrated arm: its configuration is the true joint angles
        (:meth:`true_angles`) in axis order; error frames and tool vectors fixed at their values."""
        self.data: pin.Data = self.model.createData()
        """The model's workspace, reused by every call (one thread at a time; :meth:`copy` gives
        another thread its own)."""
        self.tool_frames: list[int] = [self.model.getFrameId(link) for link in arm.tool_links]
        """Pinocchio frame ids of the tools' points (the tool links), in tool order."""
        n = arm.n_axes
        self._axes = self._joints.axes
        self._direct = self.model.nq == n and bool(np.array_equal(self._axes, np.arange(n)))
        stated = arm.stated_limits
        free = np.isnan(stated).any(axis=1)  # a continuous joint: no limits stated
        lo = np.where(free, -UNLIMITED_TURNS * 2 * np.pi, stated[:, 0] - DEGREE_MARGIN)
        hi = np.where(free, UNLIMITED_TURNS * 2 * np.pi, stated[:, 1] + DEGREE_MARGIN)
        slack = ANGLE_SLACK + max((float(np.abs(m.values).max()) for m in params.encoder_maps.values()),
                                  default=0.0)
        self._bounds = {"readouts": (lo, hi), "angles": (lo - slack, hi + slack)}
        """Per argument name, the lowest and highest value accepted per axis, rad."""
        self._free = free
        self._plain = PlainMaps(params.encoder_maps, n, lo.tolist(), hi.tolist(), self._refuse_one,
                                slack)
        self._shape = (n,)
        self._fid = self.tool_frames[0]
        self._plain_ok = not arm.couplings and self._direct and arm.n_tools == 1
        """Whether one sample may take the plain-float path (:mod:`._plain_maps`)."""
        self._fast = self._plain_ok and not params.extensions
        """... and needs no extension term either."""
        self._terms = term_values(params)  # looked up where the parameters were made
        self._keys = list(params.extensions)
        self._rotation = params.rotation()
        self._translation = np.asarray(params.translation, dtype=float)

    def __reduce__(self) -> tuple[type[CalibratedArm], tuple[Arm, Parameters]]:
        """Pickle as the arm and the parameters (the model is rebuilt on the other side)."""
        return (CalibratedArm, (self.arm, self.parameters))

    def copy(self) -> CalibratedArm:
        """Return a calibrated arm sharing this one's model, with its own Pinocchio data."""
        other = object.__new__(CalibratedArm)
        other.__dict__.update(self.__dict__)
        other.data = self.model.createData()
        return other

    # ------------------------------------------------------------------ names
    @property
    def n_axes(self) -> int:
        """Number of axes (readout columns)."""
        return self.arm.n_axes

    @property
    def axis_names(self) -> list[str]:
        """The axes' joint names in readout order."""
        return list(self.arm.axis_names)

    @property
    def tool_names(self) -> list[str]:
        """The tools' names (``tool=`` of every method), in tool order."""
        return list(self.arm.tool_names)

    @property
    def tool_links(self) -> list[str]:
        """The tools' frames in :attr:`model` (and ``compact.urdf``) by name, in tool order.

        The links the measured points are: an inverse kinematics' frame task names one.
        """
        return list(self.arm.tool_links)

    def configuration(self, readouts: np.ndarray, *,
                      columns: Mapping[str, np.ndarray] | None = None,
                      direction: np.ndarray | None = None) -> np.ndarray:
        """Return :attr:`model`'s configuration at readouts: :meth:`true_angles` in its entries.

        The same as :meth:`true_angles` for a serial arm; a model with further configuration
        entries (a tree's joints on no tool's chain) has them at zero.

        Args:
            readouts: encoder readouts, shape (n_axes,) or (N, n_axes), rad.
            columns: per-sample inputs of extension terms (see :meth:`true_angles`).
            direction: motion directions for backlash terms (see :meth:`true_angles`).

        Returns:
            Shape (nq,) or (N, nq), rad.
        """
        angles = self.true_angles(readouts, columns=columns, direction=direction)
        out = self._configurations(np.atleast_2d(angles))
        return out[0] if angles.ndim == 1 else out

    def to_arm_frame(self, points: np.ndarray) -> np.ndarray:
        """Return points given in the instrument's frame (``frame="mt"``) in the arm's own frame.

        The inverse of the calibration's ``base_to_mt`` (paper Eq. 4): e.g. a laser tracker's
        measured points as targets of an inverse kinematics on :attr:`model`.

        Args:
            points: shape (3,) or (N, 3), m, in the instrument's frame.

        Returns:
            Shape like ``points``, m, in the arm's frame (r-CS).
        """
        p = np.asarray(points, dtype=float)
        if p.ndim not in (1, 2) or p.shape[-1] != 3 or not np.isfinite(p).all():
            raise ArgumentError(f"points: need finite numbers, shape (3,) or (N, 3), in m; got shape "
                                f"{p.shape}")
        out: np.ndarray = (p - self._translation) @ self._rotation
        return out

    def motion_direction(self, previous: np.ndarray, readouts: np.ndarray,
                         direction: np.ndarray | None = None) -> np.ndarray:
        """Return the direction each axis last moved in after a move from ``previous``.

        What backlash terms read (``direction=`` of every method) when samples come one at a
        time: +1 or -1 where a readout changed, else the axis' earlier ``direction`` (0 before
        it first moves). For a command, pass the last commanded readouts and an estimate of the
        new ones (e.g. the target's true angles: the sign of a move is the same).

        Args:
            previous: the readouts before, shape (n_axes,), rad.
            readouts: the readouts now, shape (n_axes,), rad.
            direction: each axis' direction before, shape (n_axes,); None: zeros.

        Returns:
            Shape (n_axes,): +1, -1 or 0.
        """
        before, _ = self._readouts(previous, "previous")
        now, _ = self._readouts(readouts, "readouts")
        if before.shape != (1, self.n_axes) or now.shape != (1, self.n_axes):
            raise ArgumentError(f"previous, readouts: one sample each, shape ({self.n_axes},); got "
                                f"{np.shape(previous)} and {np.shape(readouts)}")
        last = np.zeros(self.n_axes) if direction is None else np.asarray(direction, dtype=float)
        if last.shape != (self.n_axes,) or not np.isin(last, (-1.0, 0.0, 1.0)).all():
            raise ArgumentError(f"direction: need +1, -1 or 0 per axis, shape ({self.n_axes},); got "
                                f"{last.tolist()}")
        step = np.sign(now[0] - before[0])
        out: np.ndarray = np.where(step != 0.0, step, last)
        return out

    # ------------------------------------------------------------------ angles
    def true_angles(self, readouts: np.ndarray, *, columns: Mapping[str, np.ndarray] | None = None,
                    direction: np.ndarray | None = None) -> np.ndarray:
        """Return the true joint angles of readouts: :attr:`model`'s configuration, rad.

        The encoder maps, the couplings (a coupled axis' readout is not read: its angle follows
        its coupling) and the extension terms' angle errors. Lateral tilts and scale terms are
        not joint angles: :meth:`position` applies them. (A plain Pinocchio model of the URDF
        holds a continuous joint as the cosine and sine of its angle; :attr:`model` the angle.)

        Args:
            readouts: encoder readouts, shape (n_axes,) or (N, n_axes), rad.
            columns: per-sample inputs of extension terms by file column name, SI, each shape
                (N,) (e.g. ``{"temp_c": ...}``).
            direction: the direction each axis last moved in (+1, -1, 0), shape like readouts,
                for backlash terms; default: from the row order of a batch, 0 for one sample.

        Returns:
            Shape like ``readouts``, rad.
        """
        if self._fast and columns is None and (vals := self._one(readouts)) is not None:
            return np.array(self._plain.forward(vals, "readouts")[0])
        q, one = self._readouts(readouts, "readouts")
        angles = self._true(q, self._change(q, columns, direction))
        return angles[0] if one else angles

    def readouts(self, angles: np.ndarray, *, columns: Mapping[str, np.ndarray] | None = None,
                 direction: np.ndarray | None = None) -> np.ndarray:
        """Return the readouts that give these true joint angles: the inverse of :meth:`true_angles`.

        For commanding the arm through its calibration (inverse kinematics on :attr:`model`
        gives true angles; the controller takes readouts). The maps are inverted exactly
        (:meth:`~aacmm_pin.model.encoder_map.EncoderMap.inverse`); extension terms by a
        fixed-point iteration (their angle errors change slowly with the readouts) to
        :data:`INVERSE_TOLERANCE`. A coupled axis' readout is its coupling of the others'.

        Args:
            angles: true joint angles, shape (n_axes,) or (N, n_axes), rad (a coupled axis' value
                is not read).
            columns: per-sample inputs of extension terms (see :meth:`true_angles`).
            direction: motion directions for backlash terms (see :meth:`true_angles`).

        Returns:
            Readouts, shape like ``angles``, rad.

        Raises:
            ArgumentError: for bad ``angles``, or if the iteration does not settle.
        """
        if self._fast and columns is None and (vals := self._one(angles)) is not None and (
                inverse := self._plain.inverse(vals, "angles")) is not None:
            return np.array(inverse)
        theta, one = self._readouts(angles, "angles")
        q = self._inverse_maps(theta)
        if self.parameters.extensions:
            for _ in range(_INVERSE_ITERATIONS):
                change = self._change(q, columns, direction)
                assert change is not None
                new = self._inverse_maps(theta - change.offsets)
                moved = float(np.max(np.abs(new - q), initial=0.0))
                q = new
                if moved <= INVERSE_TOLERANCE:
                    break
            else:
                raise ArgumentError(f"angles: the readouts of these angles did not settle within "
                                    f"{_INVERSE_ITERATIONS} steps (last move {moved:.3g} rad)")
        q = self.arm.fill_readouts(q)
        return q[0] if one else q

    # ------------------------------------------------------------------ the tool
    def position(self, readouts: np.ndarray, *, tool: str | int | None = None, frame: str = "r",
                 columns: Mapping[str, np.ndarray] | None = None,
                 direction: np.ndarray | None = None) -> np.ndarray:
        """Return the tool's point for readouts: exactly :func:`aacmm_pin.predict`, m.

        Args:
            readouts: encoder readouts, shape (n_axes,) or (N, n_axes), rad.
            tool: the tool's name or index (:attr:`tool_names`); None: the arm's only tool.
            frame: ``"r"`` (the arm's own frame, default) or ``"mt"`` (the instrument's).
            columns: per-sample inputs of extension terms (see :meth:`true_angles`).
            direction: motion directions for backlash terms (see :meth:`true_angles`).

        Returns:
            Shape (3,) for one sample, (N, 3) for N, m.
        """
        if self._plain_ok and frame == "r" and tool is None and (
                vals := self._one(readouts)) is not None:
            angles = np.array(self._plain.forward(vals, "readouts")[0])
            change = self._change(np.array([vals]), columns, direction)
            if change is None or not change.moves_point:  # else predict's tilt or twist columns
                if change is not None:
                    angles += change.offsets[0]
                pin.forwardKinematics(self.model, self.data, angles)
                point: np.ndarray = pin.updateFramePlacement(self.model, self.data,
                                                             self._fid).translation.copy()
                return point if change is None else point * change.scale[0]
        q, one = self._readouts(readouts, "readouts")
        self._check_frame(frame)
        samples = self._samples(q, columns, direction)
        change = None if samples is None else terms_adjustment(self._terms, samples, self.n_axes)
        points = self._joints.positions(q, self._tool(tool, len(q)), change, samples)
        if frame == "mt":
            points = points @ self._rotation.T + self._translation
        return points[0] if one else points

    def placement(self, readouts: np.ndarray, *, tool: str | int | None = None, frame: str = "r",
                  columns: Mapping[str, np.ndarray] | None = None,
                  direction: np.ndarray | None = None) -> np.ndarray:
        """Return the tool frame's placement, a homogeneous transform (4 x 4), m.

        Its translation is :meth:`position`; its rotation that of the tool link at the true
        joint angles (lateral tilts and frame twists of extension terms move the point only).

        Args:
            readouts: encoder readouts, shape (n_axes,) or (N, n_axes), rad.
            tool: the tool's name or index; None: the arm's only tool.
            frame: ``"r"`` (the arm's own frame, default) or ``"mt"`` (the instrument's).
            columns: per-sample inputs of extension terms (see :meth:`true_angles`).
            direction: motion directions for backlash terms (see :meth:`true_angles`).

        Returns:
            Shape (4, 4) for one sample, (N, 4, 4) for N.
        """
        if self._fast and frame == "r" and tool is None and columns is None and (
                vals := self._one(readouts)) is not None:
            pin.forwardKinematics(self.model, self.data, np.array(self._plain.forward(vals,
                                                                                      "readouts")[0]))
            placement: np.ndarray = pin.updateFramePlacement(self.model, self.data,
                                                             self._fid).homogeneous
            return placement
        q, one = self._readouts(readouts, "readouts")
        self._check_frame(frame)
        change = self._change(q, columns, direction)
        angles = self._true(q, change)
        rows = self._tool(tool, len(q))
        out = np.empty((len(q), 4, 4))
        for i, (theta, fid) in enumerate(zip(self._configurations(angles),
                                             np.asarray(self.tool_frames)[rows])):
            pin.forwardKinematics(self.model, self.data, theta)
            out[i] = pin.updateFramePlacement(self.model, self.data, int(fid)).homogeneous
        if change is not None:  # tilts and scale move the point: predict's, on the same change
            out[:, :3, 3] = self._joints.positions(q, rows, change)
        if frame == "mt":
            out[:, :3, :] = self._rotation @ out[:, :3, :]
            out[:, :3, 3] += self._translation
        return out[0] if one else out

    def jacobian(self, readouts: np.ndarray, *, tool: str | int | None = None, frame: str = "r",
                 columns: Mapping[str, np.ndarray] | None = None,
                 direction: np.ndarray | None = None) -> np.ndarray:
        """Return the tool frame's Jacobian with respect to the readouts, shape (6, n_axes).

        Rows: the velocity of the tool frame's origin (m/rad), then its angular velocity
        (rad/rad), both along the axes of ``frame`` (Pinocchio's ``LOCAL_WORLD_ALIGNED``); column
        j is d/d(readout j): the joint's column times the slope of its map and through the
        couplings (a coupled axis has no readout: a zero column). The extension terms' angle
        errors enter the angles at which it is taken, not its columns (their change with the
        readouts is second order); a scale term scales the velocity rows; lateral tilt and frame
        terms, which move the point (:meth:`position`), are left out (their change is of their size times
        the rotation, second order too).

        Args:
            readouts: encoder readouts, shape (n_axes,) or (N, n_axes), rad.
            tool: the tool's name or index; None: the arm's only tool.
            frame: ``"r"`` (the arm's own frame, default) or ``"mt"`` (the instrument's).
            columns: per-sample inputs of extension terms (see :meth:`true_angles`).
            direction: motion directions for backlash terms (see :meth:`true_angles`).

        Returns:
            Shape (6, n_axes) for one sample, (N, 6, n_axes) for N.
        """
        if self._fast and frame == "r" and tool is None and columns is None and (
                vals := self._one(readouts)) is not None:
            one_angles, slopes = self._plain.forward(vals, "readouts")
            jac: np.ndarray = pin.computeFrameJacobian(self.model, self.data, np.array(one_angles),
                                                       self._fid, _WORLD) * slopes
            return jac
        q, one = self._readouts(readouts, "readouts")
        self._check_frame(frame)
        change = self._change(q, columns, direction)
        corrected, slope = correct_with_slopes(q, self.parameters.encoder_maps)
        slope[:, self.arm.coupled] = 0.0
        angles = self.arm.joint_angles(corrected, None if change is None else change.offsets)
        fids = np.asarray(self.tool_frames)[self._tool(tool, len(q))]
        out = np.empty((len(q), 6, self.n_axes))
        for i, (theta, fid) in enumerate(zip(self._configurations(angles), fids)):
            out[i] = pin.computeFrameJacobian(self.model, self.data, theta, int(fid),
                                              _WORLD)[:, self._axes]
        if self.arm.couplings:
            out = out @ self.arm.coupling_matrix
        out *= slope[:, None, :]
        if change is not None:
            out[:, :3, :] *= change.scale[:, None, None]
        if frame == "mt":
            out[:, :3, :] = self._rotation @ out[:, :3, :]
            out[:, 3:, :] = self._rotation @ out[:, 3:, :]
        return out[0] if one else out

    # ------------------------------------------------------------------ inner
    def _readouts(self, values: np.ndarray, name: str) -> tuple[np.ndarray, bool]:
        """Return values as (N, n_axes) floats and whether one sample was given; check them."""
        try:
            q = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise ArgumentError(f"{name}: need numbers, shape ({self.n_axes},) or (N, "
                                f"{self.n_axes}), in rad; got {type(values).__name__}") from None
        one = q.ndim == 1
        if q.ndim not in (1, 2) or q.shape[-1] != self.n_axes:
            raise ArgumentError(f"{name}: need shape ({self.n_axes},) or (N, {self.n_axes}): one "
                                f"value per axis of the arm ({', '.join(self.arm.axis_names)}), in "
                                f"rad; got shape {q.shape}")
        q = q.reshape(-1, self.n_axes)
        lo, hi = self._bounds.get(name, self._bounds["readouts"])
        if not ((q >= lo) & (q <= hi)).all():  # NaN fails too
            self._refuse(q, name)
        return q, one

    def _refuse_one(self, values: list[float], name: str) -> None:
        """Raise the one-line error for one sample's values (see :meth:`_refuse`)."""
        self._refuse(np.array([values]), name)

    def _refuse(self, q: np.ndarray, name: str) -> None:
        """Raise the one-line error for the first bad value of q (not finite, or degrees)."""
        bad = ~np.isfinite(q)
        if bad.any():
            i, a = np.argwhere(bad)[0]
            raise ArgumentError(f"{name}: sample {i}, axis {a + 1} ({self.arm.axis_names[a]}) is "
                                f"{q[i, a]}: every value must be a finite number in rad")
        lo, hi = self._bounds.get(name, self._bounds["readouts"])
        i, a = np.argwhere((q < lo) | (q > hi))[0]
        limits = self.arm.stated_limits[a]
        where = (f"more than {UNLIMITED_TURNS} turns from zero (the URDF states no limits)"
                 if self._free[a] else f"beyond its limits [{limits[0]:.4g}, {limits[1]:.4g}] rad "
                 "by more than half a turn")
        raise ArgumentError(f"{name}: sample {i}, axis {a + 1} ({self.arm.axis_names[a]}) is "
                            f"{q[i, a]:.6g} rad, {where}: these look like degrees (multiply by "
                            "pi/180)")

    def _check_frame(self, frame: str) -> None:
        if frame not in ("r", "mt"):
            raise ArgumentError(f"frame: 'r' (the arm's own frame) or 'mt' (the instrument's), "
                                f"got {frame!r}")

    def _tool(self, tool: str | int | None, n: int) -> np.ndarray:
        try:
            return tool_rows(self.arm, n, tool)
        except ValueError as exc:
            raise ArgumentError(str(exc)) from None

    def _one(self, values: object) -> list[float] | None:
        """Return one sample's readouts as floats, or None where the general path must look."""
        if isinstance(values, np.ndarray):
            if values.shape != self._shape or values.dtype.kind != "f":
                return None
            out: list[float] = values.tolist()
            return out
        if isinstance(values, (list, tuple)) and len(values) == self._shape[0] and all(
                type(v) is float for v in values):
            return list(values)
        return None

    def _samples(self, q: np.ndarray, columns: Mapping[str, np.ndarray] | None,
                 direction: np.ndarray | None) -> Samples | None:
        """Return the samples the extension terms read (None without extension terms)."""
        if not self.parameters.extensions:
            return None
        cols = {}
        for key, value in (columns or {}).items():
            v = np.asarray(value, dtype=float).reshape(-1)
            if v.size == 1:
                v = np.full(len(q), float(v[0]))
            if v.shape != (len(q),) or not np.isfinite(v).all():
                raise ArgumentError(f"columns: '{key}' needs one finite value per sample ({len(q)}), "
                                    f"got shape {np.shape(value)}")
            cols[key] = v
        d = None
        if direction is not None:
            d = np.asarray(direction, dtype=float).reshape(-1, self.n_axes) if np.size(direction) \
                else np.zeros(0)
            if d.shape != q.shape or not np.isin(d, (-1.0, 0.0, 1.0)).all():
                raise ArgumentError(f"direction: need +1, -1 or 0 per axis and sample, shape "
                                    f"{q.shape if len(q) > 1 else (self.n_axes,)}; got shape "
                                    f"{np.shape(direction)}")
        return Samples(self.arm, q, columns=cols, files=("columns",), direction=d)

    def _inverse_maps(self, theta: np.ndarray) -> np.ndarray:
        """Return the readouts of N samples' angles through the maps alone, shape (N, n_axes)."""
        if len(theta) == 1 and self._plain_ok and (
                one := self._plain.inverse(theta[0].tolist(), "angles")) is not None:
            return np.array([one])
        return readouts_of_angles(theta, self.parameters.encoder_maps)

    def _change(self, q: np.ndarray, columns: Mapping[str, np.ndarray] | None,
                direction: np.ndarray | None) -> Adjustment | None:
        """Return the extension terms' change of the arm at N readouts (None without terms).

        :func:`aacmm_pin.effects.calibrated.extension_adjustment` with the terms looked up once.
        """
        if not self._terms:
            return None
        samples = self._samples(q, columns, direction)
        assert samples is not None
        out = terms_adjustment(self._terms, samples, self.n_axes)
        if samples.n == 1 and direction is None and samples.direction_known:
            raise ArgumentError(f"direction: a term of this calibration ({', '.join(self._keys)}) "
                                "reads the direction each axis last moved in, which one sample "
                                "cannot show: pass direction= (rt.motion_direction(previous, "
                                "readouts, direction) keeps it), or a batch in time order")
        return out

    def _true(self, q: np.ndarray, change: Adjustment | None) -> np.ndarray:
        """Return the true joint angles of N readouts, shape (N, n_axes), rad."""
        corrected, _ = correct_with_slopes(q, self.parameters.encoder_maps)
        angles: np.ndarray = self.arm.joint_angles(corrected, None if change is None else change.offsets)
        return angles

    def _configurations(self, angles: np.ndarray) -> np.ndarray:
        """Return the model's configurations of true joint angles (N, n_axes), shape (N, nq)."""
        if self._direct:
            return angles
        out = np.zeros((len(angles), self.model.nq))
        out[:, self._axes] = angles
        return out
