r"""Acceptance figures of an articulated arm: point articulation, P_Size, P_Form, L_Dia, E_UNI.

The figures users quote from ISO 10360-12:2016 (*Acceptance and reverification tests for
coordinate measuring systems - Part 12: Articulated arm CMMs*) and ASME B89.4.22-2004 (*Methods
for performance evaluation of articulated arm CMMs*). **The text of neither standard was available
while this module was written**: the formulas below follow the published descriptions of the tests
(test designations, number of points, what is reported) and are stated in full so that they can be
checked against the standard; clause numbers are not given because they could not be verified.
Where the standard leaves a choice (e.g. how E_UNI's test lengths are formed from our length-bar
log) the choice is said. Inputs and outputs are SI (m).

**Least-squares (Gaussian) sphere** (:func:`fit_sphere`), used by every sphere-based figure: the
centre :math:`c` and radius :math:`r` minimising :math:`\sum_i (\lVert p_i - c \rVert - r)^2`
(orthogonal distances, as in ISO 10360-6 / ASME B89.4.10 sphere fitting). Solved by SciPy's
Levenberg-Marquardt with the analytic Jacobian, started from the algebraic fit
:math:`\lVert p \rVert^2 = 2 c \cdot p + k` (linear least squares). It reproduces the NIST
reference fits (``tests/test_iso10360.py``) to 1e-6.

**Point articulation** (:func:`point_articulation`; B89.4.22's single-point articulation test, the
SPAT of ISO 10360-12 that the paper uses): N stylus centres :math:`p_i` measured with the stylus
in one seat (with the R-Test: each centre minus the measured sphere displacement, so that the
seat's motion is not counted as arm error), their mean :math:`\bar p` and deviations
:math:`\delta_i = p_i - \bar p`:

* ``max_deviation`` :math:`= \max_i \lVert \delta_i \rVert`;
* ``ranges`` :math:`= \max_i \delta_{i,a} - \min_i \delta_{i,a}` for each axis a = x, y, z;
* ``two_sigma`` :math:`= 2 \sqrt{\sum_i \lVert \delta_i \rVert^2 / (N - 1)}`.

**Probing size and form, P_Size.Sph.1x25::Tact.AArm and P_Form.Sph.1x25::Tact.AArm**
(:func:`probing_errors`): 25 points on a calibrated test sphere of diameter :math:`D_{cal}`, the
least-squares sphere (centre :math:`c`, diameter :math:`D`), radial distances
:math:`r_i = \lVert p_i - c \rVert`:

* :math:`P_{Size} = D - D_{cal}` (signed; compared as :math:`|P_{Size}|` with its MPE);
* :math:`P_{Form} = \max_i r_i - \min_i r_i` (the width of the shell centred on the least-squares
  sphere that holds every point).

**Articulated location, L_Dia.5x5:Art:Tact.AArm** (:func:`articulated_location`): the test
sphere is probed 5 times with 5 points each, in 5 different arm articulations; each group of 5
gives a least-squares sphere centre :math:`c_j`, and :math:`L_{Dia}` is the **diameter of the
smallest sphere enclosing the 5 centres** (minimum enclosing sphere, exact, by enumerating the
spheres through 1 to 4 of the centres).

**Length measurement error, E_UNI** (:func:`length_errors`): the error of calibrated test lengths
measured point to point, :math:`E = L_{measured} - L_{cal}`, and E_UNI its largest absolute value
over every test length and position. Here a test length is a calibrated socket distance of the
length bar (``bar.csv``) in one placement, measured as the distance between the mean stylus
centres of the readouts in its two sockets (as :func:`aacmm_pin.analyses.validation.validate`); the standard
measures each length with single points, several times, in several positions, which a campaign
with one readout per socket and placement reproduces exactly.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import least_squares

from aacmm_pin.data.campaign import Campaign, read_readouts
from aacmm_pin.data.csv_rows import read_rows
from aacmm_pin.data.csv_table import MAX_FILE_BYTES
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.errors import AacmmError, FileFormatError, Problem
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples

MAX_ENCLOSED = 30
"""Most points :func:`min_enclosing_sphere` accepts (it enumerates their subsets)."""


def _points3(points: Any, name: str = "points", least: int = 1) -> np.ndarray:
    """Return points as a float array of shape (N, 3), N >= least, or raise ValueError."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < least or not np.isfinite(p).all():
        raise ValueError(f"{name}: {least} or more finite points of shape (N, 3) expected, got "
                         f"shape {p.shape}")
    return p


class SphereFit(NamedTuple):
    """A least-squares sphere."""

    centre: np.ndarray
    """Centre, shape (3,), in the points' unit."""
    radius: float
    """Radius, in the points' unit."""
    fun: np.ndarray
    """Residual of every point, distance to the centre minus the radius, shape (N,)."""
    success: bool
    """Whether the solver converged."""
    nfev: int
    """Residual evaluations."""
    message: str
    """Solver message."""

    @property
    def diameter(self) -> float:
        """Diameter, twice the radius."""
        return 2.0 * self.radius


def _algebraic_sphere(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Return (centre, radius) of the linear fit |p|^2 = 2 c.p + k (points centred, scaled)."""
    a = np.column_stack([2.0 * p, np.ones(len(p))])
    sol = np.linalg.lstsq(a, (p ** 2).sum(axis=1), rcond=None)[0]
    centre = sol[:3]
    return centre, float(np.sqrt(max(sol[3] + centre @ centre, 1e-30)))


def fit_sphere(points: Any) -> SphereFit:
    r"""Fit the least-squares sphere to points (orthogonal distances).

    Minimises :math:`\sum_i (\lVert p_i - c \rVert - r)^2` with SciPy's ``least_squares``
    (Levenberg-Marquardt, analytic Jacobian) from the algebraic fit; the points are centred and
    scaled to unit RMS radius first, so the result does not depend on the units or the origin.

    Args:
        points: shape (N, 3), N >= 4, any length unit.

    Returns:
        The sphere, in the points' unit.

    Raises:
        ValueError: for fewer than 4 points or non-finite values.
    """
    p = _points3(points, least=4)
    mean = p.mean(axis=0)
    scale = float(np.sqrt(((p - mean) ** 2).sum(axis=1).mean())) or 1.0
    x = (p - mean) / scale
    c0, r0 = _algebraic_sphere(x)

    def fun(v: np.ndarray) -> np.ndarray:
        res: np.ndarray = np.linalg.norm(x - v[:3], axis=1) - v[3]
        return res

    def jac(v: np.ndarray) -> np.ndarray:
        diff = x - v[:3]
        dist = np.maximum(np.linalg.norm(diff, axis=1, keepdims=True), 1e-300)
        return np.column_stack([-diff / dist, -np.ones(len(x))])

    res = least_squares(fun, np.append(c0, r0), jac=jac, method="lm", xtol=1e-15, ftol=1e-15,
                        gtol=1e-15, max_nfev=1000)
    return SphereFit(centre=mean + scale * res.x[:3], radius=float(abs(res.x[3]) * scale),
                     fun=res.fun * scale, success=bool(res.success), nfev=int(res.nfev),
                     message=str(res.message))


class PointArticulation(NamedTuple):
    """Point articulation figures of centres measured in one seat (deviations from their mean)."""

    n: int
    """Number of centres N."""
    mean: np.ndarray
    """Mean centre, shape (3,), m."""
    deviations: np.ndarray
    """Deviation of each centre from the mean, shape (N, 3), m."""
    max_deviation: float
    """Largest distance of a centre from the mean, m."""
    ranges: np.ndarray
    """Range (max - min) of the deviations along x, y, z, shape (3,), m."""
    two_sigma: float
    """Twice sqrt(sum ``|deviation|^2`` / (N - 1)), m."""

    def to_dict(self) -> dict[str, Any]:
        """Return the figures in um (JSON form)."""
        return {"n": self.n, "mean_mm": (self.mean * 1e3).tolist(),
                "max_deviation_um": self.max_deviation * 1e6, "two_sigma_um": self.two_sigma * 1e6,
                "range_um": dict(zip("xyz", (self.ranges * 1e6).tolist()))}


def point_articulation(points: Any) -> PointArticulation:
    """Return the point articulation figures of centres measured in one seat.

    Args:
        points: stylus centres, shape (N, 3), N >= 2, in m.

    Raises:
        ValueError: for fewer than 2 points.
    """
    p = _points3(points, least=2)
    mean = p.mean(axis=0)
    dev = p - mean
    dist2 = (dev ** 2).sum(axis=1)
    return PointArticulation(
        n=len(p), mean=mean, deviations=dev, max_deviation=float(np.sqrt(dist2.max())),
        ranges=dev.max(axis=0) - dev.min(axis=0),
        two_sigma=float(2.0 * np.sqrt(dist2.sum() / (len(p) - 1))))


def spat_centres(arm: Arm, params: Parameters, campaign: Campaign,
                 use_rtest: bool = True) -> dict[int, np.ndarray]:
    """Return the stylus centres of each SPAT location, in the MT-CS, for point articulation.

    Args:
        arm: the arm.
        params: its parameters (nominal for an uncalibrated arm: then the MT-CS is the r-CS).
        campaign: campaign with a SPAT.
        use_rtest: subtract each sample's R-Test displacement (the seat's motion) from its centre.

    Returns:
        Location -> centres, shape (N_m, 3), m.

    Raises:
        AacmmError: if the campaign has no SPAT.
    """
    spat = campaign.spat
    if spat is None:
        where = "the campaign" if campaign.source is None else str(campaign.source)
        raise AacmmError(f"{where} has no SPAT (spat.csv and locations.csv): the SPAT figure needs "
                         "the stylus in an R-Test nest through many postures")
    points = stylus_positions(arm, params, spat.q, frame="mt",
                              samples=Samples.of_log(arm, spat))
    if use_rtest:
        points = points - spat.displacement
    return {int(m): points[spat.location == m] for m in campaign.location_ids}


class ProbingResult(NamedTuple):
    """Probing size and form errors on a calibrated sphere."""

    fit: SphereFit
    """Least-squares sphere of the points, m."""
    calibrated_diameter: float
    """Calibrated diameter of the test sphere, m."""
    p_size: float
    """Fitted minus calibrated diameter, m."""
    p_form: float
    """Range of the radial distances to the fitted centre, m."""

    def to_dict(self) -> dict[str, Any]:
        """Return the figures in mm and um (JSON form)."""
        return {"n": len(self.fit.fun), "centre_mm": (self.fit.centre * 1e3).tolist(),
                "diameter_mm": self.fit.diameter * 1e3,
                "calibrated_diameter_mm": self.calibrated_diameter * 1e3,
                "p_size_um": self.p_size * 1e6, "p_form_um": self.p_form * 1e6}


def probing_errors(points: Any, calibrated_diameter: float) -> ProbingResult:
    """Return P_Size and P_Form of points probed on a calibrated sphere (the test takes 25).

    Args:
        points: probed points, shape (N, 3), N >= 4, in m.
        calibrated_diameter: the sphere's calibrated diameter, m.

    Raises:
        ValueError: for fewer than 4 points or a non-positive diameter.
    """
    if not calibrated_diameter > 0:
        raise ValueError(f"calibrated_diameter: must be > 0 m, got {calibrated_diameter}")
    fit = fit_sphere(points)
    radial = fit.fun + fit.radius
    return ProbingResult(fit, float(calibrated_diameter), fit.diameter - calibrated_diameter,
                         float(radial.max() - radial.min()))


def _circumsphere(p: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Return the smallest sphere through all k <= 4 points (centre in their hull), or None."""
    if len(p) == 1:
        return p[0], 0.0
    a = p[1:] - p[0]
    gram = a @ a.T
    if np.linalg.matrix_rank(gram, tol=1e-12 * max(np.trace(gram), 1e-300)) < len(a):
        return None  # degenerate (e.g. collinear): a smaller subset gives the sphere
    lam = np.linalg.solve(gram, 0.5 * np.diag(gram))
    centre = p[0] + lam @ a
    return centre, float(np.linalg.norm(p[0] - centre))


def min_enclosing_sphere(points: Any) -> tuple[np.ndarray, float]:
    """Return (centre (3,), radius) of the smallest sphere enclosing every point.

    Exact: the smallest sphere is the circumsphere of 1 to 4 of the points (with its centre in
    their affine hull) that holds all the others; every such subset is tried.

    Args:
        points: shape (N, 3), 1 <= N <= :data:`MAX_ENCLOSED`.

    Raises:
        ValueError: for no points or more than MAX_ENCLOSED.
    """
    p = _points3(points)
    if len(p) > MAX_ENCLOSED:
        raise ValueError(f"points: at most {MAX_ENCLOSED} expected, got {len(p)}")
    tol = 1e-12 * max(float(np.abs(p - p.mean(axis=0)).max()), 1e-300)
    best: tuple[np.ndarray, float] | None = None
    for k in range(1, min(4, len(p)) + 1):
        for subset in itertools.combinations(range(len(p)), k):
            sphere = _circumsphere(p[list(subset)])
            if sphere is None or (best is not None and sphere[1] >= best[1]):
                continue
            if np.linalg.norm(p - sphere[0], axis=1).max() <= sphere[1] + tol:
                best = sphere
    assert best is not None  # the smallest enclosing sphere is always among the spheres tried
    return best


class ArticulatedLocation(NamedTuple):
    """Articulated location test: one sphere centre per articulation and L_Dia."""

    centres: np.ndarray
    """Least-squares centre of each articulation's points, shape (G, 3), m."""
    fits: list[SphereFit]
    """Sphere fit of each articulation."""
    enclosing_centre: np.ndarray
    """Centre of the smallest sphere enclosing the centres, shape (3,), m."""
    l_dia: float
    """Diameter of that sphere, m."""

    def to_dict(self) -> dict[str, Any]:
        """Return the figures in mm and um (JSON form)."""
        return {"centres_mm": (self.centres * 1e3).tolist(),
                "diameters_mm": [f.diameter * 1e3 for f in self.fits],
                "enclosing_centre_mm": (self.enclosing_centre * 1e3).tolist(),
                "l_dia_um": self.l_dia * 1e6}


def articulated_location(points: Any, groups: Any = None,
                         group_size: int = 5) -> ArticulatedLocation:
    """Return L_Dia of points probed on one sphere in several articulations (the test: 5 x 5).

    Args:
        points: probed points, shape (N, 3), m.
        groups: articulation of each point, shape (N,) (any labels, in order of appearance); None:
            consecutive groups of ``group_size``.
        group_size: points per articulation when ``groups`` is None.

    Raises:
        ValueError: for fewer than 2 articulations, fewer than 4 points in one, or a count of points
            that is not a multiple of ``group_size``.
    """
    p = _points3(points)
    if groups is None:
        if group_size < 4 or len(p) % group_size:
            raise ValueError(f"points: a multiple of group_size={group_size} (>= 4) expected, got "
                             f"{len(p)}")
        labels = np.repeat(np.arange(len(p) // group_size), group_size)
    else:
        labels = np.asarray(groups)
        if labels.shape != (len(p),):
            raise ValueError(f"groups: shape ({len(p)},) expected, got {labels.shape}")
    order = list(dict.fromkeys(labels.tolist()))
    if len(order) < 2:
        raise ValueError("points: 2 or more articulations expected")
    fits = [fit_sphere(p[labels == g]) for g in order]
    centres = np.array([f.centre for f in fits])
    centre, radius = min_enclosing_sphere(centres)
    return ArticulatedLocation(centres, fits, centre, 2.0 * radius)


class LengthErrors(NamedTuple):
    """Length measurement errors of the length bar and E_UNI."""

    placements: list[int]
    """Bar placements."""
    pairs: list[tuple[str, str]]
    """Calibrated socket pairs (from, to)."""
    errors: np.ndarray
    """Measured minus calibrated length, shape (n_placements, n_pairs), m (NaN: not measured)."""
    e_uni: float
    """Largest absolute error, m."""

    def to_dict(self) -> dict[str, Any]:
        """Return the errors and E_UNI in um (JSON form)."""
        return {"e_uni_um": self.e_uni * 1e6, "placements": [
            {"placement": int(k), **{f"{a}{b}_um": float(e * 1e6) for (a, b), e in
                                     zip(self.pairs, errs)}}
            for k, errs in zip(self.placements, self.errors)]}


def e_uni(errors: Any) -> float:
    """Return E_UNI, the largest absolute length error (NaN entries ignored), in their unit.

    Raises:
        ValueError: if there is no finite error.
    """
    e = np.asarray(errors, dtype=float)
    if not np.isfinite(e).any():
        raise ValueError("errors: no finite length error")
    return float(np.nanmax(np.abs(e)))


def length_errors(arm: Arm, params: Parameters, campaign: Campaign) -> LengthErrors:
    """Return the length errors of every bar placement and pair, and E_UNI.

    Raises:
        AacmmError: if the campaign has no length-bar data.
    """
    from aacmm_pin.analyses.validation import validate

    result = validate(arm, params, campaign)
    return LengthErrors(result.placements, result.pairs, result.errors, e_uni(result.errors))


def read_points(path: str | Path) -> tuple[np.ndarray | None, np.ndarray | None,
                                          np.ndarray | None]:
    """Read a CSV of probed points (x_mm, y_mm, z_mm) or readouts (q1_deg..qn_deg).

    An optional integer column ``group`` labels the articulation of each row (for L_Dia).

    Returns:
        (points (N, 3) in m or None, groups (N,) or None, readouts (N, n) in rad or None): points
        if the file has x_mm, y_mm, z_mm, else readouts.

    Raises:
        FileFormatError: listing every bad cell with line and column, or missing columns; a file
            larger than :data:`~aacmm_pin.data.csv_table.MAX_FILE_BYTES` or unreadable.
    """
    path = Path(path)
    rows = read_rows(path, MAX_FILE_BYTES)
    if len(rows) < 2:
        raise FileFormatError([Problem(path, None, None, "a header row and data rows expected")])
    header = rows[0][1]
    problems: list[Problem] = []

    def column(name: str, kind: type) -> np.ndarray:
        k = header.index(name)
        out = []
        for line, row in rows[1:]:
            try:
                value = kind(row[k])
                if not np.isfinite(value):
                    raise ValueError
            except (ValueError, IndexError):
                cell = row[k] if k < len(row) else ""
                what = "an integer" if kind is int else "a finite number"
                problems.append(Problem(path, line, name, f"{cell!r} is not {what}"))
                value = 0
            out.append(value)
        return np.array(out)

    groups = column("group", int) if "group" in header else None
    points = readouts = None
    if {"x_mm", "y_mm", "z_mm"} <= set(header):
        points = np.column_stack([column(n, float) for n in ("x_mm", "y_mm", "z_mm")]) * 1e-3
    elif "q1_deg" in header:
        if not problems:
            readouts = read_readouts(path)
    else:
        problems.append(Problem(path, rows[0][0], None,
                                "columns x_mm,y_mm,z_mm (points) or q1_deg..qn_deg (readouts) "
                                "expected"))
    if problems:
        raise FileFormatError(problems)
    return points, groups, readouts
