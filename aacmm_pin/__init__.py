"""aacmm_pin: calibrate articulated arm CMMs on Pinocchio (Ibaraki & Saito, CIRP Annals 2023)."""

from aacmm_pin.arm import DEFAULT_ARM, Arm, ErrorFrame, IdentificationModel, load_arm
from aacmm_pin.campaign import (
    Campaign,
    LengthBarLog,
    SpatLog,
    read_campaign,
    read_readouts,
    write_campaign,
    write_points,
)
from aacmm_pin.discovery import Discovery, discover
from aacmm_pin.discovery_figures import write_discovery
from aacmm_pin.encoder_map import EncoderMap, correct_readouts, node_angles
from aacmm_pin.errors import (
    AacmmError,
    ArmModelError,
    CampaignFormatError,
    FileFormatError,
    FrameNotFound,
    Problem,
)
from aacmm_pin.export import write_calibration
from aacmm_pin.identification import Calibration, IdentificationError, identify, measured_positions
from aacmm_pin.kinematics import StylusJacobians, predict, stylus_jacobians, stylus_positions
from aacmm_pin.parameters import Parameters, read_parameters, write_parameters
from aacmm_pin.planning import Plan, plan
from aacmm_pin.simulate import Simulation, SimulationConfig, simulate_campaign, write_simulation
from aacmm_pin.uncertainty import MonteCarloResult, monte_carlo
from aacmm_pin.validation import ValidationResult, validate
from aacmm_pin.viewer import View, view

__version__ = "0.1.0"

__all__ = [
    "Calibration", "Discovery", "discover", "write_discovery",
    "IdentificationError", "MonteCarloResult", "Plan", "ValidationResult",
    "identify", "measured_positions", "monte_carlo", "plan", "View", "view",
    "validate", "write_calibration",
    "DEFAULT_ARM", "AacmmError", "Arm", "ArmModelError", "Campaign", "CampaignFormatError",
    "EncoderMap", "ErrorFrame", "FileFormatError", "FrameNotFound", "IdentificationModel",
    "LengthBarLog", "Parameters", "Problem", "Simulation", "SimulationConfig", "SpatLog",
    "StylusJacobians", "correct_readouts", "load_arm", "node_angles", "predict",
    "read_campaign", "read_parameters", "read_readouts", "simulate_campaign", "stylus_jacobians",
    "stylus_positions", "write_campaign", "write_parameters", "write_points", "write_simulation",
]
