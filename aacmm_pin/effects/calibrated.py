"""The calibrated arm: the model's kinematics with every extension term of the parameters applied.

These are the functions the rest of the package (and a user) calls: they compute the extensions'
change of the arm (:class:`~aacmm_pin.model.kinematics.Adjustment`) with the effect library and
hand it to :mod:`aacmm_pin.model.kinematics`. Parameters without extensions give exactly the
model's kinematics.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from aacmm_pin.effects.base import Term, TiltTerm
from aacmm_pin.effects.forward import adjustment
from aacmm_pin.model import kinematics
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.kinematics import (
    Adjustment,
    JointKinematics,
    StylusJacobians,
    ToolIndex,
    solve_ik,
)
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples


def extension_adjustment(arm: Arm, params: Parameters, readouts: np.ndarray,
                         samples: Samples | None) -> Adjustment | None:
    """Return the extensions' change of the arm at the readouts (None without extensions).

    ``samples`` gives what the terms depend on (temperature, motion, any per-sample column); None
    (or samples of other readouts) builds them from the readouts alone (row order as time order).
    """
    if not params.extensions:
        return None
    q = np.atleast_2d(np.asarray(readouts, dtype=float))
    if q.ndim != 2 or q.shape[1] != arm.n_axes:  # as the model's kinematics say it, first
        raise ValueError(f"readouts: need shape (N, {arm.n_axes}) in rad, got {np.shape(readouts)}")
    if samples is None or not samples.matches(q):
        samples = Samples(arm, q)
    return adjustment(params, samples, arm.n_axes)


def held_columns(arm: Arm, readouts: np.ndarray, columns: Mapping[str, float]) -> Samples:
    """Return samples of the readouts (N, n_axes), rad, with every column held at one value.

    ``columns``: file name -> value, SI (e.g. ``{"temp_c": 21.3}``): the conditions of readouts
    that were never measured (a planned posture).
    """
    q = np.atleast_2d(np.asarray(readouts, dtype=float))
    return Samples(arm, q, columns={k: np.full(q.shape[0], float(v)) for k, v in columns.items()})


def needs_tilts(terms: Iterable[Term]) -> bool:
    """Whether some of the terms' columns need the stylus Jacobians' tilt columns (tilt terms)."""
    return any(isinstance(t, TiltTerm) for t in terms)


def stylus_positions(arm: Arm, params: Parameters, readouts: np.ndarray, frame: str = "r",
                     samples: Samples | None = None, *, tool: ToolIndex = None) -> np.ndarray:
    """Return stylus sphere centres for N readouts, shape (N, 3), in m.

    Args:
        arm: the arm.
        params: calibrated parameters (maps, DH values, tool, X0 for the MT-CS, extensions).
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"r"`` (r-CS, the arm's own frame) or ``"mt"`` (the R-Test's MT-CS).
        samples: per-sample columns (temperature, motion, ...) for extensions that need them.
        tool: which tool each sample measures (see :data:`~aacmm_pin.model.kinematics.ToolIndex`).
    """
    return kinematics.stylus_positions(arm, params, readouts, frame, samples, tool=tool,
                                       adjust=extension_adjustment(arm, params, readouts, samples))


def stylus_jacobians(arm: Arm, params: Parameters, readouts: np.ndarray, frame: str = "r",
                     samples: Samples | None = None, *, tool: ToolIndex = None,
                     tilts: bool = False) -> StylusJacobians:
    """Return stylus centres and their analytic Jacobians for N readouts.

    Args:
        arm: the arm.
        params: parameters at which to linearise.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        frame: ``"r"`` (the arm's own frame, the r-CS; the default, as everywhere) or ``"mt"``
            (the instrument's MT-CS, with X0 and translation).
        samples: per-sample columns for extensions that need them.
        tool: which tool each sample measures; each sample's Jacobian is its own tool frame's.
        tilts: also the columns of each joint's lateral tilts (:attr:`StylusJacobians.tilts`).
    """
    return kinematics.stylus_jacobians(arm, params, readouts, frame, samples, tool=tool,
                                       adjust=extension_adjustment(arm, params, readouts, samples),
                                       tilts=tilts)


def predict(arm: Arm, params: Parameters, readouts: np.ndarray, samples: Samples | None = None,
            *, tool: ToolIndex = None) -> np.ndarray:
    """Return stylus centres in the r-CS for N readouts with the *runtime* model, shape (N, 3), m.

    This is what a robotics stack does with a calibrated arm: wrap the readouts with the encoder
    maps (and the extensions' changes), then run forward kinematics of the URDF whose error
    frames hold the calibrated values.

    Args:
        arm: the nominal arm.
        params: calibrated parameters.
        readouts: encoder readouts, shape (N, n_axes), in rad.
        samples: per-sample columns for extensions that need them.
        tool: which tool each sample measures.
    """
    return kinematics.predict(arm, params, readouts, samples, tool=tool,
                              adjust=extension_adjustment(arm, params, readouts, samples))


def stylus_ik(arm: Arm, params: Parameters, targets: np.ndarray, rng: np.random.Generator,
              starts: np.ndarray | None = None, iterations: int = 25, *,
              columns: Mapping[str, float] | None = None) -> np.ndarray:
    """Return readouts (N, n_axes) putting the stylus centre of ``params`` on targets in the r-CS.

    See :func:`~aacmm_pin.model.kinematics.solve_ik` (the same arguments); targets shape (N, 3), m.
    The Newton steps use the joint Jacobian only (:class:`~aacmm_pin.model.kinematics.JointKinematics`).
    ``columns``: per-sample columns (file name -> value, SI, e.g. ``temp_c``) every target is
    reached at, for extensions that read them (None: none).
    """
    joints = JointKinematics(arm, params)

    def position_jacobian(q: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        samples = None if not columns else held_columns(arm, q, columns)
        return joints.position_jacobian(q, adjust=extension_adjustment(arm, params, q, samples))

    return arm.fill_readouts(solve_ik(position_jacobian, targets, arm.joint_limits, rng,
                                      iterations, starts))  # coupled columns: their couplings
