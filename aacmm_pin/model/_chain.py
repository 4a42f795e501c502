r"""Batched forward kinematics and frame Jacobians of a Pinocchio model, vectorised over samples.

Pinocchio stays the model: the joint placements, joint axes, parents, supports and frame
placements are read once from a :class:`pinocchio.Model` whose joints are all 1-DOF revolute or
prismatic (``JointModelRX/RY/RZ``, ``PX/PY/PZ`` or their ``Unaligned`` forms, one configuration
entry each); the products along the chain are then evaluated for N samples at once with numpy,
in chunks of samples (bounded memory, cache-sized arrays).

Each joint j keeps its placement in a basis :math:`B_j` whose z column is the joint axis, so that
every joint turns (or slides) about its own z: with :math:`S_j = {}^oR_j B_j`,

.. math::
    S_j = S_{parent} \, (B_{parent}^T R_{pl,j} B_j) \, R_z(q_j), \qquad
    o_j = o_{parent} + S_{parent} B_{parent}^T t_{pl,j} \; [+ \, S_j e_z \, q_j \text{ prismatic}]

and the world axis is :math:`S_j e_z`. The linear rows of the frame Jacobian in
``LOCAL_WORLD_ALIGNED`` at a point p are :math:`z_j \times (p - o_j)` (revolute) and :math:`z_j`
(prismatic) for the joints supporting the frame, zero for the others.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

CHUNK = 4096
"""Samples per chunk: large enough to amortise the per-joint numpy calls, small enough to stay in
cache."""
_ALIGNED = {"RX": (True, 0), "RY": (True, 1), "RZ": (True, 2),
            "PX": (False, 0), "PY": (False, 1), "PZ": (False, 2)}


def _basis(axis: np.ndarray) -> np.ndarray:
    """Return a right-handed orthonormal basis (columns) whose third column is the unit ``axis``."""
    z = axis / np.linalg.norm(axis)
    k = int(np.argmin(np.abs(z)))
    x = _cross(np.eye(3)[k], z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, _cross(z, x), z])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the cross product of two 3-vectors (as ``np.cross``, same operations, ~30x faster)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


class BatchedChain:
    """Forward kinematics and frame Jacobians of a Pinocchio model for N configurations at once.

    Args:
        model: a Pinocchio model whose joints are 1-DOF revolute or prismatic joints.

    Raises:
        ValueError: naming the first joint of another type.
    """

    def __init__(self, model: pin.Model):
        self.nq: int = model.nq
        """Configuration size of the model."""
        self.nv: int = model.nv
        """Velocity size (Jacobian columns) of the model."""
        n = model.njoints
        self.parents = [int(p) for p in model.parents]
        self.revolute = np.zeros(n, dtype=bool)
        self.idx_q = np.zeros(n, dtype=np.int64)
        self.idx_v = np.zeros(n, dtype=np.int64)
        bases = [np.eye(3)] * n
        for j in range(1, n):
            joint = model.joints[j]
            kind = joint.shortname().removeprefix("JointModel")
            if kind in _ALIGNED:
                revolute, k = _ALIGNED[kind]
                axis = np.eye(3)[k]
            elif kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
                revolute, axis = kind.startswith("Revolute"), np.asarray(joint.extract().axis, dtype=float)
            else:
                raise ValueError(f"model: joint '{model.names[j]}' is {joint.shortname()}; batched "
                                 "kinematics needs 1-DOF revolute or prismatic joints")
            self.revolute[j] = revolute
            self.idx_q[j], self.idx_v[j] = joint.idx_q, joint.idx_v
            bases[j] = _basis(axis)
        self.rotation: list[np.ndarray] = [np.eye(3)] * n
        """Per joint, :math:`B_{parent}^T R_{pl} B_j`."""
        self.offset: list[np.ndarray] = [np.zeros(3)] * n
        """Per joint, :math:`B_{parent}^T t_{pl}`."""
        for j in range(1, n):
            placement, back = model.jointPlacements[j], bases[self.parents[j]].T
            self.rotation[j] = back @ placement.rotation @ bases[j]
            self.offset[j] = back @ placement.translation
        self._bases = bases
        self._model = model
        self._frames: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}
        self._ancestors: dict[int, frozenset[int]] = {}

    def frame(self, frame_id: int) -> tuple[int, np.ndarray, np.ndarray]:
        """Return a frame's parent joint, its supporting joints (root excluded) and its offset.

        The offset is the frame's translation in the parent joint's basis (see the module).
        """
        if frame_id not in self._frames:  # read once: the kinematics ask for it on every call
            frame = self._model.frames[frame_id]
            joint = int(frame.parentJoint)
            support = np.array([int(j) for j in self._model.supports[joint]][1:], dtype=np.int64)
            support.setflags(write=False)
            self._frames[frame_id] = (joint, support,
                                      self._bases[joint].T @ frame.placement.translation)
        return self._frames[frame_id]

    def _forward(self, q: np.ndarray) -> _Pose:
        """Return the joints' placements for configurations q (one chunk, shape (n, nq))."""
        n, count = q.shape[0], len(self.parents)
        vary = np.ptp(q, axis=0) != 0 if n > 1 else np.zeros(q.shape[1], dtype=bool)
        pose = _Pose([0] * count, [np.eye(3)] * count, [np.zeros(3)] * count, {}, {})
        for j in range(1, count):
            parent = self.parents[j]
            anchor = pose.anchor[parent]
            rot = pose.rotation[parent] @ self.rotation[j]
            off = pose.offset[parent] + pose.rotation[parent] @ self.offset[j]
            qj = q[:, self.idx_q[j]]
            if not vary[self.idx_q[j]]:  # the same for every sample: a constant after the anchor
                pose.anchor[j] = anchor
                if self.revolute[j]:
                    c, s = np.cos(qj[0]), np.sin(qj[0])
                    rot = rot @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
                else:
                    off = off + rot[:, 2] * qj[0]
                pose.rotation[j], pose.offset[j] = rot, off
                continue
            pose.anchor[j] = j
            if anchor == 0:
                m = np.broadcast_to(rot, (n, 3, 3)).copy()
                org = np.broadcast_to(off, (n, 3)).copy()
            else:
                flat = pose.frames[anchor].reshape(3 * n, 3)
                m = (flat @ rot).reshape(n, 3, 3)
                org = pose.origins[anchor] + (flat @ off).reshape(n, 3)
            if self.revolute[j]:
                c, s = np.cos(qj)[:, None], np.sin(qj)[:, None]
                x, y = m[:, :, 0].copy(), m[:, :, 1].copy()
                m[:, :, 0] = c * x + s * y
                m[:, :, 1] = c * y - s * x
            else:
                org += m[:, :, 2] * qj[:, None]
            pose.frames[j], pose.origins[j] = m, org
        return pose

    def _point(self, pose: _Pose, fid: int, rows: np.ndarray) -> np.ndarray:
        """Return the origin of frame ``fid`` for the chunk's ``rows``, shape (len(rows), 3)."""
        joint, _, offset = self.frame(fid)
        anchor = pose.anchor[joint]
        local = pose.offset[joint] + pose.rotation[joint] @ offset
        point: np.ndarray
        if anchor == 0:
            point = np.broadcast_to(local, (rows.size, 3)).copy()
            return point
        point = pose.origins[anchor][rows] + pose.frames[anchor][rows] @ local
        return point

    def positions(self, q: np.ndarray, frames: np.ndarray) -> np.ndarray:
        """Return the origin of frame ``frames[i]`` at configuration ``q[i]``, shape (N, 3).

        Args:
            q: configurations, shape (N, nq).
            frames: Pinocchio frame id per sample, shape (N,).
        """
        out = np.empty((q.shape[0], 3))
        for lo in range(0, q.shape[0], CHUNK):
            pose = self._forward(q[lo:lo + CHUNK])
            for fid, rows in _groups(frames[lo:lo + CHUNK]):
                out[lo + rows] = self._point(pose, fid, rows)
        return out

    def jacobians(self, q: np.ndarray, frames: np.ndarray, columns: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Return frame origins (N, 3) and the linear rows of their Jacobians (N, 3, nv).

        The Jacobian is Pinocchio's frame Jacobian in ``LOCAL_WORLD_ALIGNED`` (rows 0-2): columns of
        joints not supporting a sample's frame are zero. The columns of the joints placed at a
        constant transform after the same moving joint (the anchor) are computed in the anchor's
        frame with one product, then turned into the world frame.

        Args:
            q: configurations, shape (N, nq).
            frames: Pinocchio frame id per sample, shape (N,).
            columns: the velocity indices to return, in this order (default: all, shape (nv,)).
        """
        pos, jac, _ = self._jacobians(q, frames, columns, None)
        return pos, jac

    def jacobian_blocks(self, q: np.ndarray, frames: np.ndarray, first: np.ndarray,
                        second: np.ndarray, out: tuple[np.ndarray, np.ndarray] | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return frame origins (N, 3) and two blocks of Jacobian columns, (N, 3, F) and (N, 3, S).

        The columns ``first`` and ``second`` of :meth:`jacobians` (velocity indices), each block
        contiguous: a caller that keeps the first and only reads the second holds no memory for
        the second's columns. ``out``: arrays for the origins and the first block, written
        (a caller's buffers, reused from call to call: no fresh pages to fault in).
        """
        pos, jac, extra = self._jacobians(q, frames, first, second, out)
        assert extra is not None
        return pos, jac, extra

    def _jacobians(self, q: np.ndarray, frames: np.ndarray, columns: np.ndarray | None,
                   second: np.ndarray | None, out: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """:meth:`jacobians`, and the columns ``second`` in an array of their own (None: none).

        ``out``: the arrays of the origins and of ``columns``' block, written (else new ones).
        """
        n = q.shape[0]
        columns = np.arange(self.nv) if columns is None else np.asarray(columns)
        pos, jac = out if out is not None else (np.empty((n, 3)), np.empty((n, 3, columns.size)))
        extra = None if second is None else np.empty((n, 3, len(second)))
        whole = np.empty((self.nv, 3, min(CHUNK, n)))  # one block for every chunk of samples
        for lo in range(0, n, CHUNK):
            pose = self._forward(q[lo:lo + CHUNK])
            size = min(CHUNK, n - lo)
            block = whole[:, :, :size]  # joint-major: contiguous column writes
            block.fill(0.0)
            for fid, rows in _groups(frames[lo:lo + CHUNK]):
                point = self._point(pose, fid, rows)
                pos[lo + rows] = point
                support = self.frame(fid)[1]
                anchors = np.array([pose.anchor[j] for j in support], dtype=np.int64)
                for anchor in np.unique(anchors):
                    joints = support[anchors == anchor]
                    cols = self._columns(pose, int(anchor), joints, point, rows)  # (J, 3, n)
                    if rows.size == size:
                        block[self.idx_v[joints]] = cols
                    else:
                        block[np.ix_(self.idx_v[joints], np.arange(3), rows)] = cols
            jac[lo:lo + size] = block[columns].transpose(2, 1, 0)
            if extra is not None:
                extra[lo:lo + size] = block[second].transpose(2, 1, 0)
        return pos, jac, extra

    def joint_jacobians(self, q: np.ndarray, frames: np.ndarray, joints: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        r"""Return frame origins (N, 3) and their Jacobian's columns of a few joints (N, 3, J).

        The columns of :meth:`jacobians` for the configuration indices ``joints`` only, each taken
        directly in the world frame (:math:`z_j \times (p - o_j)` or :math:`z_j`): the cheap
        Jacobian of inverse kinematics, which needs no other column.

        Args:
            q: configurations, shape (N, nq).
            frames: Pinocchio frame id per sample, shape (N,).
            joints: configuration indices of the joints, shape (J,).
        """
        by_q = {int(self.idx_q[j]): j for j in range(1, len(self.parents))}
        ids = [by_q[int(k)] for k in np.asarray(joints, dtype=np.int64)]
        n = q.shape[0]
        pos = np.empty((n, 3))
        jac = np.zeros((n, 3, len(ids)))
        for lo in range(0, n, CHUNK):
            pose = self._forward(q[lo:lo + CHUNK])
            for fid, rows in _groups(frames[lo:lo + CHUNK]):
                point = self._point(pose, fid, rows)
                pos[lo + rows] = point
                support = set(self.frame(fid)[1].tolist())
                cols = [c for c, j in enumerate(ids) if j in support]
                axes = np.empty((len(cols), rows.size, 3))
                arms = np.empty((len(cols), rows.size, 3))
                for i, c in enumerate(cols):
                    axes[i], origin = self._axis(pose, ids[c], rows)
                    arms[i] = point - origin
                block = np.empty((len(cols), rows.size, 3))  # z x (p - o), or z (prismatic)
                for k, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
                    block[:, :, k] = axes[..., a] * arms[..., b] - axes[..., b] * arms[..., a]
                prismatic = ~self.revolute[[ids[c] for c in cols]]
                block[prismatic] = axes[prismatic]
                if rows.size == min(CHUNK, n - lo) and len(cols) == len(ids):
                    jac[lo:lo + rows.size] = block.transpose(1, 2, 0)
                else:
                    jac[np.ix_(lo + rows, np.arange(3), np.array(cols))] = block.transpose(1, 2, 0)
        return pos, jac

    def _axis(self, pose: _Pose, joint: int, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return a joint's world axis and origin for the chunk's ``rows``, each (len(rows), 3).

        Shape (1, 3) (the same for every row) where the joint does not move in this chunk.
        """
        anchor = pose.anchor[joint]
        if anchor == joint:
            return pose.frames[joint][rows][:, :, 2], pose.origins[joint][rows]
        rot, off = pose.rotation[joint], pose.offset[joint]
        if anchor == 0:
            return rot[None, :, 2], off[None]
        frame = pose.frames[anchor][rows]
        return frame @ rot[:, 2], pose.origins[anchor][rows] + frame @ off

    def tilt_columns(self, q: np.ndarray, frames: np.ndarray, joints: np.ndarray) -> np.ndarray:
        r"""Return d(frame origin)/d(lateral tilts of joints), shape (N, 3, J, 2), m/rad.

        A tilt of joint j is a small rotation about the x and y columns :math:`u_x, u_y` of
        :math:`S_j` (its basis after its own motion: the lateral axes of the frame in which
        Pinocchio's RNEA reports the joint's transmitted force) on the child side of the joint,
        so the columns are :math:`u \times (p - o_j)`; zero where j does not support the frame.

        Args:
            q: configurations, shape (N, nq).
            frames: Pinocchio frame id per sample, shape (N,).
            joints: configuration indices of the tilted joints, shape (J,).
        """
        joints = np.asarray(joints, dtype=np.int64)
        by_q = {int(self.idx_q[j]): j for j in range(1, len(self.parents))}
        ids = [by_q[int(k)] for k in joints]
        n = q.shape[0]
        out = np.zeros((n, 3, joints.size, 2))
        for lo in range(0, n, CHUNK):
            pose = self._forward(q[lo:lo + CHUNK])
            for fid, rows in _groups(frames[lo:lo + CHUNK]):
                point = self._point(pose, fid, rows)
                support = set(self.frame(fid)[1].tolist())
                for col, j in enumerate(ids):
                    if j not in support:
                        continue
                    lateral, origin = self._lateral(pose, j, rows)
                    d = point - origin
                    for k in range(2):
                        out[lo + rows, :, col, k] = np.cross(lateral[..., k], d)
        return out

    def twist_columns(self, q: np.ndarray, frames: np.ndarray, moved: np.ndarray) -> np.ndarray:
        r"""Return d(frame origin)/d(small twists of other frames), shape (N, 3, M, 6).

        A twist :math:`(v, \omega)` of frame m, in m's own axes (Pinocchio's ``LOCAL`` convention:
        linear first), moves every point attached after m (m among the point's frame's ancestors
        through ``parentFrame``, or m itself) by :math:`R_m v + R_m \omega \times (p - o_m)`, so
        the columns are :math:`[R_m, \; -[p - o_m]_\times R_m]`; zero where m is not an ancestor.

        Args:
            q: configurations, shape (N, nq).
            frames: Pinocchio frame id of each sample's point, shape (N,).
            moved: Pinocchio frame ids of the moved frames, shape (M,).
        """
        moved = np.asarray(moved, dtype=np.int64)
        n = q.shape[0]
        out = np.zeros((n, 3, moved.size, 6))
        for lo in range(0, n, CHUNK):
            pose = self._forward(q[lo:lo + CHUNK])
            for fid, rows in _groups(frames[lo:lo + CHUNK]):
                point = self._point(pose, fid, rows)
                above = self.ancestors(fid)
                for col, m in enumerate(moved.tolist()):
                    if m not in above:
                        continue
                    rot = np.broadcast_to(self._rotation(pose, m, rows), (rows.size, 3, 3))
                    arm = point - self._point(pose, m, rows)
                    out[lo + rows, :, col, :3] = rot
                    for k in range(3):
                        out[lo + rows, :, col, 3 + k] = np.cross(rot[:, :, k], arm)
        return out

    def ancestors(self, frame_id: int) -> frozenset[int]:
        """Return a frame and every frame it hangs from (``parentFrame`` up to the universe)."""
        if frame_id not in self._ancestors:
            chain, current = {frame_id}, frame_id
            while current != 0:
                current = int(self._model.frames[current].parentFrame)
                chain.add(current)
            self._ancestors[frame_id] = frozenset(chain)
        return self._ancestors[frame_id]

    def _rotation(self, pose: _Pose, fid: int, rows: np.ndarray) -> np.ndarray:
        """Return frame ``fid``'s world rotation for the chunk's ``rows``, (len(rows), 3, 3) or (3, 3)."""
        frame = self._model.frames[fid]
        joint = int(frame.parentJoint)
        local: np.ndarray = pose.rotation[joint] @ self._bases[joint].T @ frame.placement.rotation
        anchor = pose.anchor[joint]
        if anchor == 0:
            return local
        rotation: np.ndarray = pose.frames[anchor][rows] @ local
        return rotation

    def basis(self, joint: int) -> np.ndarray:
        """Return joint ``joint``'s basis B_j in its own (Pinocchio joint) frame: z is its axis."""
        return self._bases[joint]

    def _lateral(self, pose: _Pose, joint: int, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return a joint's lateral axes and origin in the world frame.

        The axes are the x and y columns of S_j (after its own motion), shape (n, 3, 2) or (3, 2);
        the origin has shape (n, 3) or (3,).
        """
        anchor = pose.anchor[joint]
        if anchor == joint:
            return pose.frames[joint][rows][:, :, :2], pose.origins[joint][rows]
        rot, off = pose.rotation[joint], pose.offset[joint]
        if anchor == 0:
            return rot[:, :2], off
        frame = pose.frames[anchor][rows]
        return frame @ rot[:, :2], pose.origins[anchor][rows] + frame @ off

    def _columns(self, pose: _Pose, anchor: int, joints: np.ndarray, point: np.ndarray,
                 rows: np.ndarray) -> np.ndarray:
        r"""Return the Jacobian columns of ``joints`` (all placed after ``anchor``), (J, 3, n).

        In the anchor's frame, a joint at constant rotation A and offset a has the axis
        :math:`k = A e_z` and the column :math:`k \times (d - a)` (revolute) or k (prismatic), with
        d the point in the anchor's frame: one product :math:`[k]_\times d - e` for all joints.
        """
        axes = np.array([pose.rotation[j][:, 2] for j in joints])             # (J, 3)
        offsets = np.array([pose.offset[j] for j in joints])
        rev = self.revolute[joints]
        skew = np.zeros((joints.size, 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
        skew -= skew.transpose(0, 2, 1)
        skew[~rev] = 0.0
        const = np.where(rev[:, None], np.cross(axes, offsets), -axes)        # (J, 3)
        d = point
        if anchor != 0:
            frame = pose.frames[anchor][rows]
            d = np.einsum("nki,nk->ni", frame, point - pose.origins[anchor][rows])
        local: np.ndarray = ((skew.reshape(-1, 3) @ d.T).reshape(joints.size, 3, -1)
                             - const[:, :, None])
        if anchor == 0:
            return local
        world: np.ndarray = np.empty_like(local)
        for i in range(3):  # world = S @ local, sample by sample, as 3 x 3 vector products
            world[:, i] = (frame[:, i, 0] * local[:, 0] + frame[:, i, 1] * local[:, 1]
                           + frame[:, i, 2] * local[:, 2])
        return world


class _Pose(NamedTuple):
    """Joint placements of one chunk: each joint is a constant transform after its anchor.

    An anchor is a joint whose configuration differs between the samples (or the root, 0): its
    frame S (n, 3, 3) and origin (n, 3) are per sample; every other joint sits at a constant
    rotation and offset in its anchor's frame.
    """

    anchor: list[int]
    """Per joint, its anchor (itself for a moving joint)."""
    rotation: list[np.ndarray]
    """Per joint, its basis in the anchor's frame (3, 3)."""
    offset: list[np.ndarray]
    """Per joint, its origin in the anchor's frame (3,)."""
    frames: dict[int, np.ndarray]
    """Per anchor, S, shape (n, 3, 3)."""
    origins: dict[int, np.ndarray]
    """Per anchor, its origin, shape (n, 3)."""


def _groups(frames: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Return (frame id, row indices) for each distinct frame id."""
    ids = np.unique(frames)
    if ids.size == 1:
        return [(int(ids[0]), np.arange(frames.size))]
    return [(int(f), np.flatnonzero(frames == f)) for f in ids]
