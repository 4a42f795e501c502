"""Units and defaults, in one place: SI inside the package, these factors at its boundaries.

Multiply a value in the named unit by the factor to get SI (``5 * UM`` is 5e-6 m); divide an SI
value by it to display it (``error / ARCSEC``). The defaults are the paper's stated uncertainties
(Ibaraki & Saito 2023, Section 5) and the map node step it uses.
"""

from __future__ import annotations

import math

MM = 1e-3
"""One millimetre, m."""
UM = 1e-6
"""One micrometre, m."""
ARCSEC = math.pi / 180 / 3600
"""One arc second, rad."""

SIGMA_RTEST = 2e-6
"""Standard uncertainty of an R-Test reading per coordinate, m (paper Section 5: 2 um)."""
SIGMA_LOCATION = 3e-6
"""Standard uncertainty of an R-Test nest (zero) position per coordinate, m (paper: 3 um)."""
SIGMA_POINT = 20e-6
"""Default standard uncertainty of an absolute tool point per coordinate, m: a laser tracker's
stated accuracy over a robot's workspace (e.g. 15 um + 6 um/m); a ``sigma_um`` column overrides it."""
SIGMA_MOTION_CAPTURE = 100e-6
"""Default standard uncertainty of a motion-capture marker per coordinate, m: optical systems
state about 0.1 mm over a room-sized volume (ten times a laser tracker's 10-20 um)."""
INSTRUMENT_NOISE: dict[str, dict[str, float]] = {
    "laser tracker": {"point": SIGMA_POINT},
    "motion capture": {"point": SIGMA_MOTION_CAPTURE},
    "r-test": {"rtest": SIGMA_RTEST, "location": SIGMA_LOCATION},
}
"""Stated noise per kind of measurement (m) that a campaign's instrument implies, by the name
``campaign.json`` gives it (``"instrument": "motion capture"``); the kinds it does not set keep
their defaults, and ``noise_um`` overrides any."""
NOISE_MIN = 1e-9
"""Smallest stated noise (standard uncertainty per coordinate) accepted, m: nothing measures a
position better than about 1 nm (a laser interferometer's resolution); below it the weights of a
fit span more than its floating-point precision (a row of 1e-15 m outweighs 20 um ones by 1e10)."""
NOISE_MAX = 1.0
"""Largest stated noise accepted, m: about an arm's reach (1-4 m); a measurement that uncertain
carries nothing (a unit error: m written where um was meant)."""


def noise_problem(value: float) -> str | None:
    """Return why a stated noise ``value`` (m) is not plausible, or None if it is.

    Plausible: finite and within :data:`NOISE_MIN` to :data:`NOISE_MAX`; the text gives the bounds in
    um, as the files and options state noise.
    """
    if not (math.isfinite(value) and value > 0):
        return f"a positive noise expected, got {value!r} m"
    if not NOISE_MIN <= value <= NOISE_MAX:
        return (f"{value / UM:.3g} um is not a plausible noise: nothing measures a position better "
                f"than {NOISE_MIN / UM:g} um (1 nm) or worse than {NOISE_MAX / UM:g} um (an arm's "
                "reach)")
    return None


SIGMA_SOCKET = 2e-6
"""Standard uncertainty of a stylus centre seated in a length-bar socket, per coordinate, m (the
arm's readout noise at a fixed point, as for an R-Test reading); used when the bar is a
calibration input."""
SIGMA_BAR = 1e-6
"""Standard uncertainty of a calibrated length-bar distance, m (a calibrated bar: ~1 um)."""
SOCKET_PRIOR = 1.0
"""Prior standard deviation of a length-bar socket's position per coordinate, m: unknown, so
loose (the socket's own readouts and the bar's lengths determine it)."""
RTEST_RANGE = 2e-3
"""Largest R-Test displacement accepted per coordinate, m: an R-Test's displacement sensors
measure a few hundred um; a reading beyond 2 mm is a unit or sensor error (a 1 mm glitch within
that range is left to the fit's outlier check, :mod:`aacmm_pin.fit.robust`)."""
BAR_LENGTH_MIN = 1e-3
BAR_LENGTH_MAX = 10.0
"""Calibrated bar lengths accepted, m (1 mm to 10 m)."""
MAX_COORDINATE = 100.0
"""Largest absolute coordinate accepted (R-Test zero positions, tracker points), m."""
MAX_PARAMETER = 100.0
"""Largest absolute value accepted in parameters.json (DH errors, tool, translation, angles, maps,
extensions), m or rad: beyond it a value is not a calibration (a unit error or a corrupt file)."""
TEMPERATURE_RANGE_C = (-50.0, 150.0)
"""Arm temperatures accepted, deg C."""
RADIAN_MIN_ROWS = 20
"""A readouts file of at least this many rows whose every readout column lies within +-2 pi and
moves by 1 or more is taken for radians (see :mod:`aacmm_pin.data.campaign`)."""
STEP_DEG = 5.0
"""Encoder map node step, deg (nodes at -180, -175, ..., 175 deg)."""
REFERENCE_TEMPERATURE_C = 20.0
"""ISO 1 reference temperature, deg C: thermal terms are zero there."""

SIMULATOR_EFFECTS = ("dh", "encoder", "rtest", "compliance", "thermal", "backlash",
                     "lateral_compliance", "crosstalk")
"""Effects the simulator (:mod:`aacmm_pin.analyses.simulate`) can switch on."""
DEFAULT_SIMULATOR_EFFECTS = ("dh", "encoder", "rtest")
"""Effects a simulated campaign has by default: the paper's model."""
