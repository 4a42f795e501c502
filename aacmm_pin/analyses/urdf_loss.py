"""How far a calibration's URDF alone is from the whole calibration, over its campaign's poses.

A URDF holds the DH values and the tool vectors (in its joint origins), not the encoder maps nor the
extension terms (compliance, thermal expansion, ...): a robotics stack that loads it alone and takes
the readouts as joint angles is off by the maps' and the terms' effect. :func:`urdf_alone_loss`
measures that over the poses the calibration was identified from: every tool's position by
Pinocchio's forward kinematics of the (compact) URDF at the readouts, against
:func:`aacmm_pin.effects.calibrated.predict` (maps and extensions applied), in the r-CS.

SI inside (m); the report's key and the texts in um.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from aacmm_pin.effects.calibrated import predict
from aacmm_pin.model._chain import BatchedChain
from aacmm_pin.model.arm import Arm, build_model
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples
from aacmm_pin.model.urdf_tree import UrdfTree
from aacmm_pin.units import UM

__all__ = ["REPORT_KEY", "UrdfLoss", "loss_line", "urdf_alone_loss"]

REPORT_KEY = "urdf_alone_loss_um"
"""The key of ``report.json`` holding :meth:`UrdfLoss.to_dict`."""


class UrdfLoss(NamedTuple):
    """The 3D distance between the URDF alone and the whole calibration over a campaign's poses."""

    rms: float
    """RMS of the distance over every pose and tool, m."""
    max: float
    """Largest distance, m."""
    n_poses: int
    """Number of poses (readout rows; each evaluated for every tool)."""
    missing: tuple[str, ...]
    """What the URDF does not hold, in words (``encoder maps of A1, A2``); empty: nothing."""

    @property
    def why(self) -> str:
        """Why the URDF alone differs, in words (or that it holds the whole calibration)."""
        if not self.missing:
            return "the URDF holds the whole calibration (no encoder maps, no extension terms)"
        return f"{' and '.join(self.missing)} are not in the URDF"

    def to_dict(self) -> dict[str, Any]:
        """Return the report's entry: ``rms``, ``max`` (um), ``n_poses``, ``why``."""
        return {"rms": round(self.rms / UM, 4), "max": round(self.max / UM, 4),
                "n_poses": self.n_poses, "why": self.why}

    def comment(self, sidecar: str) -> str:
        """Return the URDF's top comment: the loss and where the rest of the calibration is.

        Args:
            sidecar: the parameters file that holds all of it (``compact.json``).
        """
        if not self.missing:
            return (f"This URDF holds the whole calibration: no encoder maps and no extension "
                    f"terms (0 um from the full calibration over the {self.n_poses} poses of its "
                    f"campaign).")
        return (f"This URDF alone is {self.rms / UM:.3g} um RMS / {self.max / UM:.3g} um max from "
                f"the full calibration over the {self.n_poses} poses of its campaign: "
                f"{self.why}. For all of it, wrap the readouts with {sidecar} beside it: "
                "aacmm_pin.load_calibrated(folder).true_angles(readouts) gives this URDF's "
                "joint angles, .position(readouts) the point (aacmm-pin predict alike).")


def _missing(arm: Arm, params: Parameters) -> tuple[str, ...]:
    axes = [f"A{k}" for k, emap in sorted(params.encoder_maps.items())
            if np.any(np.asarray(emap.values) != 0)]
    out = [f"encoder maps of {', '.join(axes)}"] if axes else []
    if params.extensions:
        out.append(f"extension terms {', '.join(params.extensions)}")
    return tuple(out)


def urdf_positions(arm: Arm, urdf: UrdfTree, q: np.ndarray) -> np.ndarray:
    """Return every tool's position with the URDF alone: readouts as joint angles, no corrections.

    Forward kinematics of Pinocchio's model of the URDF (evaluated for all samples at once,
    :class:`~aacmm_pin.model._chain.BatchedChain`); movable joints on no tool's chain at zero, a
    coupled axis at its coupling of the readouts (a URDF ``<mimic>``). The axes are found by name.

    Args:
        arm: the arm (its axes, tools and couplings; the URDF has its joint and link names).
        urdf: the URDF (e.g. the compact one).
        q: readouts, shape (N, n_axes), rad.

    Returns:
        Positions in the r-CS, shape (n_tools, N, 3), m.
    """
    return _urdf_chain(arm, urdf)(q)


def _urdf_chain(arm: Arm, urdf: UrdfTree) -> Callable[[np.ndarray], np.ndarray]:
    """Return :func:`urdf_positions` of this URDF as a function of the readouts (model built once)."""
    tree = urdf.copy()
    for name in arm.off_chain:
        tree.make_fixed(name)
    model = build_model(tree)
    idx = [model.joints[model.getJointId(name)].idx_q for name in arm.axis_names]
    chain = BatchedChain(model)
    frames = [model.getFrameId(link) for link in arm.tool_links]

    def positions(q: np.ndarray) -> np.ndarray:
        angles = arm.joint_angles(np.atleast_2d(q))
        config = np.zeros((len(angles), model.nq))
        config[:, idx] = angles
        return np.stack([chain.positions(config, np.full(len(angles), fid)) for fid in frames])

    return positions


LOSS_BLOCK = 65536
"""Readouts per block of :func:`urdf_alone_loss` without extensions (a multiple of the chain's
own block: every readout's arithmetic that of one call): the configurations and corrected
readouts (about 250 bytes per readout) exist for one block only, not for 1.6M readouts at once."""


def urdf_alone_loss(arm: Arm, params: Parameters, urdf: UrdfTree, poses: Sequence[Samples]
                    ) -> UrdfLoss:
    """Return how far the URDF alone is from the whole calibration over the poses.

    Every pose (readout row) counts. Without extensions the poses are taken
    :data:`LOSS_BLOCK` at a time (the same distances, in the same order: the same numbers); with
    extensions one part at a time (their terms may depend on the neighbouring samples).

    Args:
        arm: the arm the parameters calibrate (with its error frames).
        params: the calibrated parameters (maps, extensions, tool vectors, DH values).
        urdf: the calibrated URDF (error frames and tools at the parameters' values, or folded:
            :func:`aacmm_pin.model.compact_urdf.compact_urdf`).
        poses: the campaign's samples (readouts, shape (N, n_axes), rad, and the per-sample
            columns the extensions need), one part per file.

    Raises:
        AacmmError: if an extension needs a column the samples do not have.
    """
    alone_of = _urdf_chain(arm, urdf)
    distances = []
    for part in poses:
        block = part.n if params.extensions else LOSS_BLOCK
        per_tool: list[list[np.ndarray]] = [[] for _ in range(arm.n_tools)]
        for lo in range(0, part.n, max(block, 1)):
            hi = min(part.n, lo + block)
            q, samples = part.q[lo:hi], part if hi - lo == part.n else None
            alone = alone_of(q)
            for k in range(arm.n_tools):
                full = predict(arm, params, q, samples, tool=k)
                per_tool[k].append(np.linalg.norm(alone[k] - full, axis=1))
        distances += [d for blocks in per_tool for d in blocks]  # by part, tool, then readout
    d = np.concatenate(distances) if distances else np.zeros(0)
    return UrdfLoss(float(np.sqrt(np.mean(d**2))) if d.size else 0.0,
                    float(d.max()) if d.size else 0.0, sum(p.n for p in poses), _missing(arm, params))


def loss_line(report: dict[str, Any] | None, sidecar: str) -> str | None:
    """Return one line saying the report's URDF-alone loss, or None when it has none.

    Args:
        report: ``report.json``'s content.
        sidecar: the parameters file with all of the calibration, as the line names it.
    """
    entry = (report or {}).get(REPORT_KEY)
    if not isinstance(entry, dict):
        return None
    if entry.get("rms") == 0 and entry.get("max") == 0:
        return str(entry.get("why"))  # the URDF holds the whole calibration
    return (f"the URDF alone is {entry.get('rms'):.3g} um RMS / {entry.get('max'):.3g} um max from "
            f"the full calibration over {entry.get('n_poses')} poses: {entry.get('why')}; "
            f"{sidecar} holds all of it")
