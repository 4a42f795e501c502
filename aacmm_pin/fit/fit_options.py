"""How :func:`aacmm_pin.identify` fits: its options, checked once (:class:`FitOptions`)."""

from __future__ import annotations

from dataclasses import dataclass

from aacmm_pin.data.campaign import StatedNoise
from aacmm_pin.effects.base import Term
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.units import STEP_DEG, noise_problem

MODELS = ("dh", "proposed")
MAX_NFEV_PER_SOLVE = 200
"""Most residual evaluations of one solve of a fit when no cap of the whole fit is given."""
NESTS = ("auto", "estimate", "fixed")
"""How :func:`identify` treats the R-Test nests' offsets."""


@dataclass(frozen=True)
class FitOptions:
    """How :func:`identify` fits: its keyword arguments, checked once (see there)."""

    model: str = "proposed"
    """``"dh"`` or ``"proposed"``."""
    use_rtest: bool = True
    """Each sample's R-Test displacement (True) or each location's mean (False)."""
    start: Parameters | None = None
    """Start values; None: nominal, X0 and translation fitted to the location centres."""
    step_deg: float = STEP_DEG
    """Map node step, deg."""
    map_axes: tuple[int, ...] | None = None
    """Axes whose maps are estimated (None: all, for ``proposed``)."""
    loss: str = "linear"
    """scipy loss of every solve."""
    f_scale: float | None = None
    """Residual scale of a robust loss, m (None: 3 x the solve's sigma)."""
    sigma: float | None = None
    """Noise per coordinate of the campaign's main kind (R-Test readings, else points without a
    ``sigma_um`` column), m; None: :attr:`noise`'s."""
    sigma_location: float | None = None
    """Prior standard deviation of each R-Test zero position per coordinate, m; None:
    :attr:`noise`'s."""
    noise: StatedNoise | None = None
    """The stated noise per kind of measurement; None: the campaign's (``campaign.json``: its
    ``noise_um``, else its instrument's), else the defaults. Every solve weighs its rows and
    priors with it and the residual is judged against it (:func:`solve_noise`)."""
    max_nfev: int | None = None
    """Most residual evaluations of the whole fit (every solve of it together); None: each solve
    stops after :data:`MAX_NFEV_PER_SOLVE` (see :attr:`solve_nfev`)."""
    jac: str = "analytic"
    """``"analytic"`` or a scipy finite-difference scheme."""
    progress: bool = False
    """Show progress."""
    extensions: tuple[Term, ...] = ()
    """Further terms of the effect library to estimate."""
    use_bar: bool = False
    """Fit the length-bar readouts too."""
    robust: bool = False
    """Reject outliers."""
    nests: str = "auto"
    """The R-Test nests' offsets: ``"auto"``, ``"estimate"`` or ``"fixed"``."""

    @property
    def solve_nfev(self) -> int:
        """Most residual evaluations of one solve: ``max_nfev``, else :data:`MAX_NFEV_PER_SOLVE`."""
        return MAX_NFEV_PER_SOLVE if self.max_nfev is None else self.max_nfev

    def __post_init__(self) -> None:
        if self.jac not in ("analytic", "2-point", "3-point", "cs"):
            raise ValueError(f"jac: choose 'analytic', '2-point' or '3-point', got {self.jac!r}")
        if self.model not in MODELS:
            raise ValueError(f"model: choose from {', '.join(MODELS)}, got {self.model!r}")
        for name, value in (("sigma", self.sigma), ("sigma_location", self.sigma_location)):
            if value is not None and (why := noise_problem(value)) is not None:
                raise ValueError(f"{name}: {why}")
        if self.nests not in NESTS:
            raise ValueError(f"nests: choose from {', '.join(NESTS)}, got {self.nests!r}")
