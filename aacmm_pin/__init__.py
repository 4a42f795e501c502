"""aacmm_pin: calibrate articulated arm CMMs on Pinocchio (Ibaraki & Saito, CIRP Annals 2023).

The public names below are imported on first use (PEP 562): ``import aacmm_pin`` costs nothing,
and ``aacmm_pin.identify`` imports :mod:`aacmm_pin.fit.identification` (and Pinocchio, scipy) the
first time it is read. ``from aacmm_pin import identify`` works as usual.
"""

from __future__ import annotations

import importlib
import importlib.util
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from aacmm_pin.analyses.discovery import discover
    from aacmm_pin.analyses.discovery_results import Discovery
    from aacmm_pin.analyses.planning import Plan, plan
    from aacmm_pin.analyses.simulate import Simulation, SimulationConfig, simulate_campaign
    from aacmm_pin.analyses.uncertainty import MonteCarloResult, monte_carlo
    from aacmm_pin.analyses.validation import ValidationResult, validate
    from aacmm_pin.data.campaign import (
        ArmNames,
        read_campaign,
        read_readouts,
        write_campaign,
        write_points,
    )
    from aacmm_pin.data.columns import Column, register_column
    from aacmm_pin.data.logs import Campaign, LengthBarLog, PointLog, SpatLog, StatedNoise, read_noise
    from aacmm_pin.data.point_import import ImportResult, PointFormat, import_points
    from aacmm_pin.effects.base import (
        AngleTerm,
        BasisTerm,
        Effect,
        FrameTerm,
        MapTerm,
        MeasurementTerm,
        ScaleTerm,
        Term,
        TiltTerm,
        Variable,
    )
    from aacmm_pin.effects.calibrated import predict, stylus_jacobians, stylus_positions
    from aacmm_pin.effects.calibrated_arm import CalibratedArm
    from aacmm_pin.effects.calibrated_folder import load_calibrated
    from aacmm_pin.effects.parameters_file import read_parameters, write_parameters
    from aacmm_pin.effects.registry import load_effect_file, register_effect
    from aacmm_pin.errors import (
        AacmmError,
        ArgumentError,
        ArmModelError,
        CampaignFormatError,
        FileFormatError,
        FrameNotFound,
        MissingColumn,
        MissingExtraError,
        Problem,
    )
    from aacmm_pin.fit.identification import identify
    from aacmm_pin.fit.identification_result import Calibration
    from aacmm_pin.fit.measurements import IdentificationError, measured_positions
    from aacmm_pin.model.arm import DEFAULT_ARM, Arm, ErrorFrame, IdentificationModel, load_arm
    from aacmm_pin.model.encoder_map import EncoderMap, correct_readouts, node_angles, readouts_of_angles
    from aacmm_pin.model.kinematics import StylusJacobians
    from aacmm_pin.model.parameters import Parameters
    from aacmm_pin.model.sizes import Sizes, read_sizes, write_sizes
    from aacmm_pin.outputs.calibration_folder import CalibrationFolder, read_calibration
    from aacmm_pin.outputs.discovery_figures import write_discovery
    from aacmm_pin.outputs.export import write_calibration
    from aacmm_pin.outputs.simulation_folder import write_simulation
    from aacmm_pin.outputs.viewer import View, view

__version__ = "0.1.0"

__all__ = [
    "Calibration", "Discovery", "discover", "write_discovery",
    "IdentificationError", "MonteCarloResult", "Plan", "ValidationResult",
    "identify", "measured_positions", "monte_carlo", "plan", "View", "view",
    "validate", "write_calibration", "CalibrationFolder", "read_calibration",
    "CalibratedArm", "load_calibrated", "readouts_of_angles", "ArgumentError",
    "DEFAULT_ARM", "AacmmError", "Arm", "ArmModelError", "Campaign", "CampaignFormatError",
    "EncoderMap", "ErrorFrame", "FileFormatError", "FrameNotFound", "IdentificationModel",
    "LengthBarLog", "MissingColumn", "MissingExtraError", "Parameters", "Problem", "Simulation",
    "SimulationConfig",
    "SpatLog", "StatedNoise", "read_noise", "PointLog", "ArmNames", "Column", "register_column",
    "StylusJacobians", "correct_readouts", "load_arm", "node_angles", "predict",
    "read_campaign", "read_parameters", "read_readouts", "simulate_campaign", "stylus_jacobians",
    "stylus_positions", "write_campaign", "write_parameters", "write_points", "write_simulation",
    "Sizes", "read_sizes", "write_sizes", "import_points", "ImportResult", "PointFormat",
    # the extension point: an effect, the ways its terms act, registration
    "Effect", "Term", "AngleTerm", "ScaleTerm", "TiltTerm", "FrameTerm", "MeasurementTerm", "MapTerm",
    "BasisTerm", "Variable", "register_effect", "load_effect_file",
]

_PUBLIC: dict[str, tuple[str, ...]] = {
    # module -> the public names it defines (the same as the TYPE_CHECKING imports above)
    "model.arm": ("DEFAULT_ARM", "Arm", "ErrorFrame", "IdentificationModel", "load_arm"),
    "data.campaign": ("ArmNames", "read_campaign", "read_readouts", "write_campaign", "write_points"),
    "data.columns": ("Column", "register_column"),
    "data.point_import": ("ImportResult", "PointFormat", "import_points"),
    "data.logs": ("Campaign", "LengthBarLog", "PointLog", "SpatLog", "StatedNoise", "read_noise"),
    "analyses.discovery": ("discover",),
    "analyses.discovery_results": ("Discovery",),
    "outputs.discovery_figures": ("write_discovery",),
    "model.encoder_map": ("EncoderMap", "correct_readouts", "node_angles", "readouts_of_angles"),
    "errors": ("AacmmError", "ArgumentError", "ArmModelError", "CampaignFormatError", "FileFormatError",
               "FrameNotFound", "MissingColumn", "MissingExtraError", "Problem"),
    "outputs.export": ("write_calibration",),
    "fit.identification": ("identify",),
    "fit.identification_result": ("Calibration",),
    "fit.measurements": ("IdentificationError", "measured_positions"),
    "outputs.calibration_folder": ("CalibrationFolder", "read_calibration"),
    "model.kinematics": ("StylusJacobians",),
    "effects.calibrated": ("predict", "stylus_jacobians", "stylus_positions"),
    "effects.calibrated_arm": ("CalibratedArm",),
    "effects.calibrated_folder": ("load_calibrated",),
    "model.parameters": ("Parameters",),
    "effects.base": ("Effect", "Term", "AngleTerm", "ScaleTerm", "TiltTerm", "FrameTerm", "MeasurementTerm",
                     "MapTerm", "BasisTerm", "Variable"),
    "effects.parameters_file": ("read_parameters", "write_parameters"),
    "effects.registry": ("register_effect", "load_effect_file"),
    "analyses.planning": ("Plan", "plan"),
    "model.sizes": ("Sizes", "read_sizes", "write_sizes"),
    "analyses.simulate": ("Simulation", "SimulationConfig", "simulate_campaign"),
    "outputs.simulation_folder": ("write_simulation",),
    "analyses.uncertainty": ("MonteCarloResult", "monte_carlo"),
    "analyses.validation": ("ValidationResult", "validate"),
    "outputs.viewer": ("View", "view"),
}
_MODULE_OF = {name: module for module, names in _PUBLIC.items() for name in names}


def __getattr__(name: str) -> Any:
    """Import a public name from its module on first use (then it is a plain global).

    A submodule's name (``aacmm_pin.model.parameters``) imports that submodule, as it was an attribute
    of the package when ``__init__`` imported every module.
    """
    module = _MODULE_OF.get(name)
    if module is not None:
        value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    elif name.isidentifier() and not name.startswith("__") \
            and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        value = importlib.import_module(f"{__name__}.{name}")
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """List the public names (imported or not) beside the package's globals."""
    return sorted({*globals(), *__all__})
