"""What the model and its effects may depend on, per sample: readouts, temperature, time, motion.

:class:`Samples` bundles one log's readouts with the columns beside them (``temp_c``, ``t_s`` and
every other per-sample column by its file name, the R-Test displacement) and what follows from
them (the gravity torque on every axis, each axis' direction of motion). Build it from a campaign
log with :meth:`Samples.of_log` or, for SPATs with their displacement, :meth:`Samples.of_spat`;
join several with :meth:`Samples.concatenate`.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from aacmm_pin.data.logs import LengthBarLog, PointLog, SpatLog
from aacmm_pin.data.poses import POSE_COLUMN, pose_ids
from aacmm_pin.errors import MissingColumn
from aacmm_pin.model._chain import BatchedChain
from aacmm_pin.model.arm import Arm

_FILE_OF = {SpatLog: "spat.csv", LengthBarLog: "lengthbar.csv", PointLog: "points.csv"}
_FIELD_OF = {"dx_mm": "displacement", "dy_mm": "displacement", "dz_mm": "displacement",
             "tool": "tool", "location": "location"}
"""Columns of the files that the samples keep as a field, not in :attr:`Samples.columns`."""


class Samples:
    """What effects may depend on, per sample: readouts, temperature, time, motion, gravity.

    Args:
        arm: the arm (its URDF inertias give the gravity torques).
        q: encoder readouts, shape (N, n_axes), rad.
        temp: arm temperature, shape (N,), deg C, or None (the ``temp_c`` column).
        t: time stamps, shape (N,), s, or None (row order is then the time order; ``t_s``).
        displacement: R-Test displacement less its location's mean, shape (N, 3), m, or None.
        tool: 0-based index (in ``arm.tool_joints``) of the tool each sample measures, shape (N,),
            or None (the arm's only tool).
        location: R-Test location (or instrument group) of each sample, shape (N,), or None.
        columns: per-sample columns by file name, each shape (N,), SI (``temp`` and ``t``, when
            given, override its ``temp_c`` and ``t_s``).
        files: the files the samples were read from, named when a column is missing.
        direction: the direction each axis last moved in, shape (N, n_axes), +1, -1 or 0; None:
            from the time order (:attr:`direction`).
    """

    def __init__(self, arm: Arm, q: np.ndarray, temp: np.ndarray | None = None,
                 t: np.ndarray | None = None, displacement: np.ndarray | None = None,
                 tool: np.ndarray | None = None, location: np.ndarray | None = None, *,
                 columns: Mapping[str, np.ndarray] | None = None, files: Sequence[str] = (),
                 direction: np.ndarray | None = None):
        self.arm = arm
        self.location = None if location is None else np.asarray(location, dtype=np.int64)
        self.tool = None if tool is None else np.asarray(tool, dtype=np.int64)
        self.q = np.atleast_2d(np.asarray(q, dtype=float))
        merged = dict(columns or {})
        merged.update((name, v) for name, v in (("temp_c", temp), ("t_s", t)) if v is not None)
        self.columns: dict[str, np.ndarray] = {name: np.asarray(v, dtype=float)
                                               for name, v in merged.items()}
        """Per-sample columns by file name (``t_s``, ``temp_c``, ``temp_wrist_c``), shape (N,), SI."""
        self.files = tuple(files)
        """The files the samples come from (``spat.csv``, a readouts file), or empty."""
        self._displacement = displacement
        self._spat: SpatLog | None = None
        """The SPAT log whose displacements :attr:`displacement` takes when first asked for."""
        self._gravity: np.ndarray | None = None
        self._lateral_gravity: np.ndarray | None = None
        self._direction: np.ndarray | None = None if direction is None else np.asarray(
            direction, dtype=float)

    @classmethod
    def of_log(cls, arm: Arm, log: SpatLog | LengthBarLog | PointLog) -> Samples:
        """Return the samples of a log's readouts with its per-sample columns and tool column.

        Raises:
            ValueError: if a point names a tool the arm does not have.
        """
        tool = getattr(log, "tool", None)
        return cls(arm, log.q, tool=None if tool is None else arm.tool_index(tool),
                   columns=log.columns, files=(_FILE_OF[type(log)],))

    @classmethod
    def of_spat(cls, arm: Arm, spat: SpatLog) -> Samples:
        """Return the SPAT samples, with each R-Test displacement less its location's mean.

        The displacements are taken when first asked for (:attr:`displacement`): a fit without an
        R-Test term holds no copy of them (38 MB at 1.6M samples).
        """
        out = cls(arm, spat.q, location=spat.location, columns=spat.columns, files=("spat.csv",))
        out._spat = spat
        return out

    @property
    def displacement(self) -> np.ndarray | None:
        """R-Test displacement less its location's mean, shape (N, 3), m, or None."""
        if self._displacement is None and self._spat is not None:
            spat, self._spat = self._spat, None
            dev = spat.displacement.copy()
            for m in np.unique(spat.location):
                sel = spat.location == m
                dev[sel] -= dev[sel].mean(axis=0)
            self._displacement = dev
        return self._displacement

    @classmethod
    def concatenate(cls, parts: Sequence[Samples]) -> Samples:
        """Return the samples of several parts (of one arm), rows stacked in order.

        A column is kept when every part has it; a missing displacement is zero, a missing tool
        the first one; locations are dropped. The ``pose`` column is kept when any part has it:
        each part's poses numbered apart from the others' (a part without the column: identical
        readouts in consecutive rows are one pose, as :func:`~aacmm_pin.data.poses.pose_ids`).
        """
        names = [n for n in parts[0].columns if all(n in p.columns for p in parts)]
        disp = np.concatenate([np.zeros((x.n, 3)) if x.displacement is None else x.displacement
                               for x in parts])
        tool = None if all(x.tool is None for x in parts) else np.concatenate(
            [np.zeros(x.n, dtype=np.int64) if x.tool is None else x.tool for x in parts])
        columns = {n: np.concatenate([p.columns[n] for p in parts]) for n in names}
        if any(POSE_COLUMN in p.columns for p in parts):
            columns[POSE_COLUMN] = _joined_poses(parts)
        return cls(parts[0].arm, np.concatenate([p.q for p in parts]), displacement=disp, tool=tool,
                   columns=columns, files=tuple(dict.fromkeys(f for p in parts for f in p.files)))

    def select(self, rows: np.ndarray) -> Samples:
        """Return the samples of these rows (a boolean mask or indices), every column with them."""
        return Samples(self.arm, self.q[rows], None, None,
                       None if self.displacement is None else self.displacement[rows],
                       None if self.tool is None else self.tool[rows],
                       None if self.location is None else self.location[rows],
                       columns={k: v[rows] for k, v in self.columns.items()}, files=self.files)

    @property
    def temp(self) -> np.ndarray | None:
        """Arm temperature, shape (N,), deg C, or None (the ``temp_c`` column)."""
        return self.columns.get("temp_c")

    @property
    def t(self) -> np.ndarray | None:
        """Time stamps, shape (N,), s, or None (the ``t_s`` column)."""
        return self.columns.get("t_s")

    def column(self, name: str) -> np.ndarray:
        """Return a per-sample column by its file name, shape (N,), in SI.

        Raises:
            MissingColumn: if the samples have no such column (one line, naming it and the files
                that could hold it; an ``AacmmError`` and a ``KeyError``).
        """
        if (values := self.columns.get(name)) is not None:
            return values
        where = " or ".join(self.files) or "the readouts file"
        have = ", ".join(self.columns) or "none"
        raise MissingColumn(name, f"no column '{name}' in the samples: add it to {where} (columns "
                                  f"there: {have})")

    def has_column(self, name: str) -> bool:
        """Whether the samples hold a column of the files by its name (``temp_c``, ``dx_mm``).

        A per-sample column (:attr:`columns`), or one the samples keep as a field: the R-Test
        displacement's ``dx_mm``, ``dy_mm``, ``dz_mm``, the ``tool`` and the ``location``.
        """
        field = _FIELD_OF.get(name)
        return name in self.columns if field is None else getattr(self, field) is not None

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.q.shape[0])

    def time_in_location(self) -> np.ndarray:
        """Return the time since the first sample of each sample's location, shape (N,), s.

        Without ``t``: rows since the location's first row; without locations: since the first
        sample.
        """
        t = self.t if self.t is not None else np.arange(self.n, dtype=float)
        groups = self.location if self.location is not None else np.zeros(self.n, dtype=np.int64)
        out = np.empty(self.n)
        for m in np.unique(groups):
            sel = groups == m
            out[sel] = t[sel] - t[sel].min()
        return out

    def matches(self, q: np.ndarray) -> bool:
        """Whether these samples describe readouts ``q`` (same array or same values)."""
        return q is self.q or (q.shape == self.q.shape and bool(np.array_equal(q, self.q)))

    @property
    def gravity(self) -> np.ndarray:
        """Torque that gravity exerts on every axis at the readouts, shape (N, n_axes), N m.

        Minus Pinocchio's generalized gravity (``dV/dq``, the torque the joint must hold) of the
        nominal runtime model (URDF inertias, gravity along -z of the r-CS): a compliant joint
        deflects by ``k * torque`` with k > 0, i.e. the arm sags. Every body of the tree loads the
        axes that carry it (a torso axis carries both arms). With coupled joints (see
        :func:`gravity_torques`) at the coupled configuration, a coupled axis' own torque, the
        others' in the independent coordinates.
        """
        if self._gravity is None:
            self._gravity = gravity_torques(self.arm, self.arm.nominal_model, self.q)
        return self._gravity

    @property
    def lateral_gravity(self) -> np.ndarray:
        """Moment gravity loads every axis with about its two lateral axes, shape (N, n_axes, 2), N m.

        The x and y components, in the joint's basis (:meth:`BatchedChain.basis`: z is the joint
        axis; the lateral axes of :meth:`BatchedChain.tilt_columns`), of minus the moment the
        parent transmits to the joint's subtree in Pinocchio's RNEA at rest (``data.f[joint]``,
        in the joint frame, about its origin), nominal runtime model: a joint that gives way
        laterally by ``k * torque`` with k > 0 lets the arm sag, as :attr:`gravity` does about the
        axis (whose z component this is).
        """
        if self._lateral_gravity is None:
            model = self.arm.nominal_model
            data = model.createData()
            chain = BatchedChain(model)
            ids = [model.getJointId(name) for name in self.arm.axis_names]
            lateral = np.array([chain.basis(j)[:, :2] for j in ids])  # (n_axes, 3, 2)
            q = [model.joints[j].idx_q for j in ids]
            qs = np.zeros((self.n, model.nq))
            qs[:, q] = self.arm.joint_angles(self.q)
            zero = np.zeros(model.nv)
            moment = np.empty((self.n, len(ids), 3))
            for i, qi in enumerate(qs):
                pin.rnea(model, data, qi, zero, zero)
                moment[i] = [data.f[j].angular for j in ids]
            self._lateral_gravity = -np.einsum("aij,nai->naj", lateral, moment)
        return self._lateral_gravity

    @property
    def direction_known(self) -> bool:
        """Whether :attr:`direction` was given or has been read (e.g. by a backlash term)."""
        return self._direction is not None

    @property
    def direction(self) -> np.ndarray:
        """Direction each axis last moved in, at every sample (time order), shape (N, n_axes).

        +1 or -1: the sign of the last non-zero change of the readout, carried while the axis
        rests (backlash keeps its side until the axis reverses); 0 before the axis first moves.
        """
        if self._direction is None:
            order = np.argsort(self.t, kind="stable") if self.t is not None else np.arange(self.n)
            out = np.empty_like(self.q)
            out[order] = motion_direction(self.q[order])
            self._direction = out
        return self._direction


_DATA = threading.local()
"""The workspace and axis indices of the model :func:`gravity_torques` last ran on, one per thread
(a Pinocchio Data costs about 20 us to create and the lookups as much: more than the torques of a
few samples)."""


def gravity_torques(arm: Arm, model: pin.Model, q: np.ndarray) -> np.ndarray:
    r"""Return the torque gravity exerts on every axis, shape (N, n_axes), N m.

    Minus Pinocchio's generalized gravity of a runtime model of the arm at readouts q (N, n_axes),
    rad. With coupled joints the configuration is the coupled one (:meth:`Arm.joint_angles`) and
    the torques are :math:`T^T g` (virtual work: an independent axis also holds what its coupled
    joints transmit, :math:`g_i + \sum_c a_{ci} g_c`), a coupled axis keeps its own :math:`g_c`
    (the torque its joint and linkage carry, which its compliance bends under).
    """
    names = tuple(arm.axis_names)
    if getattr(_DATA, "model", None) is not model or _DATA.names != names:
        ids = [model.getJointId(name) for name in arm.axis_names]
        _DATA.model, _DATA.names, _DATA.data = model, names, model.createData()
        _DATA.v = [model.joints[j].idx_v for j in ids]
        _DATA.idx = [model.joints[j].idx_q for j in ids]
    data, v, idx = _DATA.data, _DATA.v, _DATA.idx
    qs = np.zeros((q.shape[0], model.nq))
    qs[:, idx] = arm.joint_angles(q)
    out: np.ndarray = -np.array([pin.computeGeneralizedGravity(model, data, qi)[v]
                                 for qi in qs]).reshape(q.shape[0], arm.n_axes)
    return out @ arm.coupling_matrix if arm.couplings else out


def motion_direction(q: np.ndarray) -> np.ndarray:
    """Return the direction each axis last moved in, row by row, shape (N, n_axes) (see above)."""
    step = np.sign(np.diff(q, axis=0, prepend=q[:1]))
    out = np.zeros_like(step)
    last = np.zeros(q.shape[1])
    for i, row in enumerate(step):
        last = np.where(row != 0, row, last)
        out[i] = last
    return out


def _joined_poses(parts: Sequence[Samples]) -> np.ndarray:
    """Return the pose of every row of the joined parts, shape (N,): 0, 1, ... per part, apart."""
    ids, start = [], 0
    for part in parts:
        part_ids = pose_ids(part.q, part.columns.get(POSE_COLUMN))
        ids.append(part_ids + start)
        start += int(part_ids.max()) + 1 if part_ids.size else 0
    return np.concatenate(ids).astype(float) if ids else np.zeros(0)
