"""A calibration folder loaded for run time: :func:`load_calibrated` -> :class:`CalibratedArm`.

A folder is read through its ``compact.json`` (the compact URDF) when it has one, else through its
``parameters.json``; both give the same points. A frame term on an error frame, which the compact
URDF folds into the joint origins, is evaluated on ``parameters.json``'s arm.
"""

from __future__ import annotations

from pathlib import Path

from aacmm_pin.effects.base import FrameTerm
from aacmm_pin.effects.calibrated_arm import CalibratedArm
from aacmm_pin.effects.parameters_file import read_parameters
from aacmm_pin.errors import ArgumentError
from aacmm_pin.model.arm import load_arm, resolve_arm_path

__all__ = ["COMPACT_PARAMETERS", "FULL_PARAMETERS", "load_calibrated"]

FULL_PARAMETERS = "parameters.json"
"""A calibration folder's parameters of its error-frame URDF (``calibrated.urdf``)."""
COMPACT_PARAMETERS = "compact.json"
"""A calibration folder's parameters of its compact URDF (``compact.urdf``: the calibrated values
folded into the joint origins), read first by :func:`load_calibrated`."""
def load_calibrated(path: str | Path, arm: str | Path | None = None) -> CalibratedArm:
    """Load a calibration for run time: a folder, or a parameters file of one.

    A folder is read through its ``compact.json`` (the compact URDF, the calibrated values folded
    into the joint origins, and the rest of the calibration) when it has one, else through its
    ``parameters.json``: both give the same points.

    Args:
        path: a calibration folder (``aacmm-pin identify --out``) or a parameters file.
        arm: the arm's URDF or embedded name instead of the one the parameters name (with a
            folder: its ``parameters.json``, whose DH values the arm's error frames take).

    Raises:
        ArgumentError: for ``arm`` with parameters that hold no DH values (``compact.json``:
            the geometry is its own URDF's).
        FileFormatError: for a missing or bad parameters file, or parameters that do not fit
            the arm (naming the file and the key).
        ArmModelError: if the URDF cannot be read.
    """
    file = Path(path)
    if file.is_dir():  # another arm takes the DH values of parameters.json
        compact = file / COMPACT_PARAMETERS
        file = compact if compact.is_file() and arm is None else file / FULL_PARAMETERS
    params = read_parameters(file)
    if arm is not None and not params.dh and _urdf_path(arm) != _urdf_path(params.arm):
        raise ArgumentError(f"arm: {file} holds no DH values (its calibrated geometry is in "
                            f"{params.arm}); give another arm with the folder or its "
                            f"{FULL_PARAMETERS}")
    # a compact URDF (compact.json: no DH values) is loaded as it is, without error frames
    loaded = CalibratedArm(load_arm(arm if arm is not None else params.arm,
                                    error_frames=bool(params.dh)), params)
    if file.name == COMPACT_PARAMETERS and _moves_a_folded_frame(loaded):
        return load_calibrated(file.with_name(FULL_PARAMETERS), arm)
    return loaded


def _moves_a_folded_frame(runtime: CalibratedArm) -> bool:
    """Whether a frame term of the calibration moves a frame its (compact) model has not.

    The compact URDF folds the error frames into the joint origins: a term on an error frame is
    evaluated on the arm of ``parameters.json``, which keeps them.
    """
    return any(isinstance(t, FrameTerm) and not runtime.model.existFrame(t.frame)
               for t, _ in runtime._terms)


def _urdf_path(arm: str | Path) -> Path:
    """Return the resolved URDF path of an arm's path or embedded name."""
    return Path(resolve_arm_path(arm)).resolve()
