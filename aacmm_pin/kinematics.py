r"""Batch kinematics: stylus centres and their Jacobians for N readouts at once.

Positions come from Pinocchio's forward kinematics; Jacobians from Pinocchio's frame Jacobian of the
identification model (:class:`aacmm_pin.arm.IdentificationModel`), in which every parameter is a
joint, so every column is analytic. Map nodes enter through the chain rule:
:math:`\partial p / \partial \Delta\theta_{n,map}(k) = \partial p / \partial \theta_n \cdot w_k(\theta^*_n)`
with the interpolation weights :math:`w_k` of :meth:`EncoderMap.weights`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin
import scipy.sparse as sp

from aacmm_pin.arm import Arm
from aacmm_pin.encoder_map import correct_readouts
from aacmm_pin.parameters import Parameters

_WORLD = pin.LOCAL_WORLD_ALIGNED


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
    """d(position)/d(tool vector), shape (N, 3, 3), dimensionless."""
    rotation: np.ndarray
    """d(position)/d(alpha0, beta0, gamma0), shape (N, 3, 3), in m/rad (zero-sized use in r-CS)."""
    translation: np.ndarray
    """d(position)/d(translation), shape (N, 3, 3), dimensionless."""
    q_readout: np.ndarray
    """The readouts used, shape (N, n_axes), in rad (for :meth:`nodes`)."""

    def nodes(self, params: Parameters, axis: int) -> sp.csr_matrix:
        """Return d(position)/d(map nodes of one axis), sparse, shape (3N, n_nodes), m/rad.

        Rows are ordered sample-major: row ``3 * i + k`` is coordinate k of sample i.
        """
        weights = params.map(axis).weights(self.q_readout[:, axis - 1])  # (N, n_nodes)
        col = self.angles[:, :, axis - 1].reshape(-1)  # (3N,)
        return sp.csr_matrix(sp.diags(col) @ sp.kron(weights, np.ones((3, 1)), format="csr"))


def _readouts_2d(readouts: np.ndarray, arm: Arm) -> np.ndarray:
    q = np.atleast_2d(np.asarray(readouts, dtype=float))
    if q.ndim != 2 or q.shape[1] != arm.n_axes:
        raise ValueError(f"readouts: need shape (N, {arm.n_axes}) in rad, got {np.shape(readouts)}")
    return q


def identification_configuration(arm: Arm, params: Parameters, readouts: np.ndarray,
                                 frame: str = "mt") -> np.ndarray:
    """Return the identification model's configurations, shape (N, nq).

    Args:
        arm: the arm.
        params: DH values, tool, X0, translation and maps.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"mt"`` to include the r-CS -> MT-CS transform, ``"r"`` for the r-CS.
    """
    if frame not in ("r", "mt"):
        raise ValueError(f"frame: choose 'r' or 'mt', got {frame!r}")
    ident = arm.identification
    q_read = _readouts_2d(readouts, arm)
    q = np.zeros((q_read.shape[0], ident.model.nq))
    if frame == "mt":
        alpha, beta, gamma = params.rotation_abc
        q[:, ident.base_idx] = [*params.translation, beta, alpha, gamma]
    q[:, ident.axis_idx] = correct_readouts(q_read, params.encoder_maps)
    q[:, ident.error_idx] = [params.dh.get(n, f.nominal) for n, f in
                             zip(arm.error_names, arm.error_frames)]
    q[:, ident.tool_idx] = params.tool
    return q


def stylus_positions(arm: Arm, params: Parameters, readouts: np.ndarray, frame: str = "r"
                     ) -> np.ndarray:
    """Return stylus sphere centres for N readouts, shape (N, 3), in m.

    Args:
        arm: the arm.
        params: calibrated parameters (maps, DH values, tool, and X0 for the MT-CS).
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"r"`` (r-CS, the arm's own frame) or ``"mt"`` (the R-Test's MT-CS).
    """
    ident = arm.identification
    model, data, fid = ident.model, ident.data, ident.stylus_frame
    q = identification_configuration(arm, params, readouts, frame)
    out = np.empty((q.shape[0], 3))
    forward, update = pin.forwardKinematics, pin.updateFramePlacement  # bound once: hot loop
    for i, qi in enumerate(q):
        forward(model, data, qi)
        out[i] = update(model, data, fid).translation
    return out


def stylus_jacobians(arm: Arm, params: Parameters, readouts: np.ndarray, frame: str = "mt"
                     ) -> StylusJacobians:
    """Return stylus centres and their analytic Jacobians for N readouts.

    Args:
        arm: the arm.
        params: parameters at which to linearise.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"mt"`` (MT-CS, with X0 and translation) or ``"r"`` (r-CS).
    """
    ident = arm.identification
    model, data, fid = ident.model, ident.data, ident.stylus_frame
    q = identification_configuration(arm, params, readouts, frame)
    n = q.shape[0]
    pos = np.empty((n, 3))
    jac = np.empty((n, 6, model.nv))
    frame_jacobian, placements = pin.computeFrameJacobian, data.oMf  # bound once: hot loop
    for i, qi in enumerate(q):
        jac[i] = frame_jacobian(model, data, qi, fid, _WORLD)
        pos[i] = placements[fid].translation
    jac = jac[:, :3]
    q_read = _readouts_2d(readouts, arm)
    angles = jac[:, :, ident.axis_idx]
    slope = np.ones_like(q_read)
    for axis in params.encoder_maps:
        slope[:, axis - 1] += params.encoder_maps[axis].slope(q_read[:, axis - 1])
    alpha, beta, gamma = ident.base_idx[[4, 3, 5]]
    return StylusJacobians(
        position=pos,
        readouts=angles * slope[:, None, :],
        angles=angles,
        dh=jac[:, :, ident.error_idx],
        tool=jac[:, :, ident.tool_idx],
        rotation=jac[:, :, [alpha, beta, gamma]],
        translation=jac[:, :, ident.base_idx[:3]],
        q_readout=q_read,
    )


def predict(arm: Arm, params: Parameters, readouts: np.ndarray) -> np.ndarray:
    """Return stylus centres in the r-CS for N readouts with the *runtime* model, shape (N, 3), m.

    This is what a robotics stack does with a calibrated arm: wrap the readouts with the encoder
    maps, then run forward kinematics of the URDF whose error frames hold the calibrated values.
    """
    model = arm.runtime_model(params.dh, params.tool)
    data = model.createData()
    fid = model.getFrameId(arm.stylus_link)
    q = correct_readouts(_readouts_2d(readouts, arm), params.encoder_maps)
    out = np.empty((q.shape[0], 3))
    for i, qi in enumerate(q):
        pin.forwardKinematics(model, data, qi)
        out[i] = pin.updateFramePlacement(model, data, fid).translation
    return out
