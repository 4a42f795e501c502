r"""Where to measure next: the SPAT that would shrink the worst map uncertainty most.

Information model (stated): the current campaign's data information :math:`J^T J / \sigma^2` over
every parameter and *every* map node (visited or not), plus a prior of the plausible sizes
(the arm's :class:`aacmm_pin.model.sizes.Sizes`: 20 arcsec for a node of the default arm, so an
unvisited node's
uncertainty is finite and equals it), plus the map-mean gauge; nest offsets are marginalised with
their prior (sigma 3 um). A candidate SPAT (an R-Test location and a posture family, postures found
by IK on the calibrated model) adds its rows; the predicted covariance follows by a low-rank
update. The map uncertainty of an axis is the RMS of its node standard uncertainties; the worst
axis is the one with the largest among the axes whose map is estimated. Only SPATs are counted:
a campaign without them is refused (:func:`check_plannable`), and absolute points beside them are
left out of the present information (the plan says so: its uncertainties are then upper bounds).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aacmm_pin.analyses.validation import bar_pairs, pair_errors, pair_weights
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.effects.calibrated import held_columns, stylus_ik
from aacmm_pin.errors import AacmmError
from aacmm_pin.fit.identifiability import GAUGE_WEIGHT, plausible_sizes
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.unknowns import Unknowns
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples
from aacmm_pin.progress import Progress
from aacmm_pin.units import ARCSEC, SIGMA_LOCATION


class PlanningError(AacmmError):
    """The campaign cannot be planned for (e.g. it has no SPAT)."""


def check_plannable(campaign: Campaign) -> None:
    """Raise PlanningError if ``campaign`` has no SPAT: the plan ranks R-Test nests and postures."""
    if campaign.spat is None or len(campaign.spat.location) == 0:
        where = "" if campaign.source is None else f"{campaign.source}: "
        raise PlanningError(
            f"{where}no SPAT (spat.csv): plan ranks where to put the R-Test next and needs the "
            "campaign's SPATs; for absolute points (points.csv) measure more poses spread over "
            "every joint's range instead (identify lists what the data leaves unidentifiable)")


@dataclass(frozen=True)
class Candidate:
    """A candidate SPAT and its predicted effect."""

    location_mt: np.ndarray
    """R-Test nest position in the MT-CS, shape (3,), m."""
    family: str
    """Posture family, e.g. ``"any posture"`` or ``"A4 in [-150, -20] deg"``."""
    starts: np.ndarray | None
    """IK start box of the family, shape (n_axes, 2), rad (None: the joint limits)."""
    postures: np.ndarray
    """Readouts of the planned postures, shape (n, n_axes), rad."""
    map_std_after: dict[int, float]
    """Predicted RMS node std per axis after adding this SPAT, rad."""
    worst_after: float
    """Predicted RMS node std of the worst axis after adding it, rad."""
    length_std_after: float | None = None
    """Predicted RMS std of the length errors after adding it, m (None without a bar)."""


@dataclass(frozen=True)
class Plan:
    """Ranked candidates (best first) and the present state."""

    worst_axis: int
    """Axis whose map is the most uncertain now."""
    map_std: dict[int, float]
    """RMS node std per axis now, rad."""
    worst_ranges: dict[int, list[tuple[float, float, float]]]
    """Axis -> angular ranges (lo_deg, hi_deg, mean node std rad) whose nodes are worst."""
    length_std: float | None
    """RMS std of the length errors now, m."""
    candidates: list[Candidate] = field(default_factory=list)
    """Candidates ranked by the predicted worst-axis map uncertainty, best first."""
    points_left_out: int = 0
    """Absolute points of the campaign not counted in the information (upper-bound uncertainties)."""

    def reduction(self, candidate: Candidate) -> float:
        """Return the share by which a candidate shrinks the worst axis' map uncertainty (0-1)."""
        return 1 - candidate.worst_after / self.map_std[self.worst_axis]

    def table(self, top: int = 10) -> str:
        """Return the plan as plain text: the worst axes and ranges, then the ``top`` candidates."""
        lines = [f"worst axis: A{self.worst_axis}, map uncertainty (RMS node std, k=1) "
                 + ", ".join(f"A{a} {v / ARCSEC:.1f}" for a, v in self.map_std.items()) + " arcsec"]
        for axis, ranges in self.worst_ranges.items():
            text = "; ".join(f"{_span(lo, hi)} deg ({s / ARCSEC:.1f} arcsec)" for lo, hi, s in ranges)
            lines.append(f"  A{axis} worst ranges: {text or 'none'}")
        if self.length_std is not None:
            lines.append(f"length-error uncertainty now: {self.length_std * 1e6:.2f} um RMS")
        if self.points_left_out:
            lines.append(f"note: the {self.points_left_out} absolute points (points.csv) are not "
                         "counted: the uncertainties above are upper bounds")
        lines.append(f"{'rank':>4}  {'nest x, y, z (mm, MT-CS)':>28}  {'family':<28} "
                     f"{'worst axis after':>17} {'reduction':>9} {'length std after':>16}")
        for rank, c in enumerate(self.candidates[:top], start=1):
            x, y, z = c.location_mt * 1e3
            length = "" if c.length_std_after is None else f"{c.length_std_after * 1e6:.2f} um"
            lines.append(f"{rank:>4}  {x:>8.1f} {y:>8.1f} {z:>9.1f}  {c.family:<28} "
                         f"{c.worst_after / ARCSEC:>12.2f} arcsec {100 * self.reduction(c):>8.1f}% "
                         f"{length:>16}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-ready summary (arcsec, um, mm, deg)."""
        def arcsec(d: dict[int, float]) -> dict[str, float]:
            return {str(a): v / ARCSEC for a, v in d.items()}
        return {
            "worst_axis": self.worst_axis, "map_std_arcsec": arcsec(self.map_std),
            "worst_ranges_deg": {str(a): [[lo, hi, s / ARCSEC] for lo, hi, s in r]
                                 for a, r in self.worst_ranges.items()},
            "length_std_um": None if self.length_std is None else self.length_std * 1e6,
            "points_left_out": self.points_left_out,
            "candidates": [{"rank": i + 1, "location_mt_mm": (c.location_mt * 1e3).tolist(),
                            "family": c.family, "n_postures": len(c.postures),
                            "worst_axis_std_after_arcsec": c.worst_after / ARCSEC,
                            "reduction_percent": 100 * self.reduction(c),
                            "map_std_after_arcsec": arcsec(c.map_std_after),
                            "length_std_after_um": None if c.length_std_after is None
                            else c.length_std_after * 1e6}
                           for i, c in enumerate(self.candidates)],
        }


class _Information:
    """Information over the full layout (all nodes of the mapped axes) for one parameter set."""

    def __init__(self, arm: Arm, params: Parameters, map_axes: tuple[int, ...], sigma: float,
                 sigma_location: float):
        self.u = Unknowns.full(arm, params, map_axes)
        self.x = self.u.full_vector(params)
        self.sigma, self.sigma_location = sigma, sigma_location
        n = self.x.size
        info = np.diag(1.0 / plausible_sizes(self.u) ** 2)
        for axis in map_axes:  # the map-mean gauge over all nodes
            row = np.zeros(n)
            row[self.u.map_slice(axis)] = GAUGE_WEIGHT / self.u.start.map(axis).n_nodes
            info += np.outer(row, row) / sigma ** 2
        self.prior = info

    def rows(self, samples: Samples) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return one SPAT's rows: data A (3n, P), nest E (3n, 3), and W (3, 3).

        ``samples``: the SPAT's readouts (n, n_axes) with their columns (what the calibration's
        extensions read, e.g. ``temp_c``). A and E are divided by sigma; W = E^T E + the nest
        offset's prior, for marginalising it.
        """
        q = samples.q
        _, jac = self.u.with_samples(samples).jacobian(self.x, q)
        a = jac.matmul(np.eye(self.x.size)) / self.sigma  # (3n, P)
        e = np.tile(np.eye(3), (len(q), 1)) / self.sigma  # d(rows)/d(nest)
        w = e.T @ e + np.eye(3) / self.sigma_location ** 2
        return a, e, w

    def add(self, info: np.ndarray, samples: Samples) -> np.ndarray:
        """Return info plus one SPAT's marginalised information (its samples: :meth:`rows`)."""
        a, e, w = self.rows(samples)
        ea = e.T @ a
        out: np.ndarray = info + a.T @ a - ea.T @ np.linalg.solve(w, ea)
        return out


def _map_std(info_inv_diag: np.ndarray, u: Unknowns) -> dict[int, np.ndarray]:
    return {a: np.sqrt(np.clip(info_inv_diag[u.map_slice(a)], 0, None)) for a in u.map_axes}


def information_now(cal: Calibration, campaign: Campaign, sigma: float | None = None,
                    sigma_location: float | None = None) -> tuple[_Information, np.ndarray]:
    """Return the information model and the present information matrix of a calibration.

    Raises:
        PlanningError: if the campaign has no SPAT.
    """
    check_plannable(campaign)
    assert campaign.spat is not None
    model = _Information(cal.unknowns.arm, cal.parameters, cal.unknowns.map_axes,
                         sigma or cal.sigma, _location(cal, sigma_location))
    info = model.prior.copy()
    spat = Samples.of_spat(model.u.arm, campaign.spat)
    for m in np.unique(campaign.spat.location):
        info = model.add(info, spat.select(campaign.spat.location == m))
    return model, info


def planned_conditions(campaign: Campaign) -> dict[str, float]:
    """Return the per-sample columns a planned SPAT is taken at: each SPAT column's median, SI.

    E.g. ``{"t_s": ..., "temp_c": 21.9}``: a calibration whose extensions read a column (thermal,
    a plugin's) needs a value for postures never measured; the campaign's typical one.
    """
    assert campaign.spat is not None
    return {k: float(np.median(v)) for k, v in campaign.spat.columns.items()}


def _span(lo_deg: float, hi_deg: float) -> str:
    """Return a range of map nodes as text: ``lo..hi``, or one value for a single node."""
    return f"{lo_deg:g}" if lo_deg == hi_deg else f"{lo_deg:g}..{hi_deg:g}"


def _worst_ranges(std: np.ndarray, nodes_deg: np.ndarray, top: int = 2
                  ) -> list[tuple[float, float, float]]:
    """Return up to ``top`` contiguous node ranges (periodic) whose std exceeds half the axis max.

    Ranked by width times mean std; each as (lo_deg, hi_deg, mean std rad).
    """
    high = std > 0.5 * std.max()
    if high.all() or not high.any():
        return [(float(nodes_deg[0]), float(nodes_deg[-1]), float(std.mean()))] if high.all() else []
    shift = int(np.argmin(high))  # start at a low node so that runs do not wrap
    order = np.roll(np.arange(std.size), -shift)
    ranges, run = [], []
    for k in list(order) + [None]:
        if k is not None and high[k]:
            run.append(k)
        elif run:
            ranges.append((float(nodes_deg[run[0]]), float(nodes_deg[run[-1]]),
                           float(std[run].mean()), len(run)))
            run = []
    ranges.sort(key=lambda r: -r[3] * r[2])
    return [(lo, hi, s) for lo, hi, s, _ in ranges[:top]]


def candidate_grid(campaign: Campaign, per_side: int = 3, half_width: float = 0.26,
                   heights: Sequence[float] = (0.0, 0.25), *, unit: float = 1.0) -> np.ndarray:
    """Return candidate R-Test nest positions around the present nests' centre, shape (k, 3), m.

    A square of ``per_side`` x ``per_side`` positions, ``half_width`` from the centre to each
    side (one position, the centre, for ``per_side`` 1), at each height above the nests (m),
    ordered by height, then x, then y: ``k = per_side**2 * len(heights)``.

    Args:
        campaign: the campaign (its nests' zero positions).
        per_side: positions along x and along y.
        half_width: from the centre to the outer positions, in ``unit``.
        heights: above the nests' centre, m.
        unit: metres per unit of ``half_width`` (the CLI's ``--spacing-mm``: ``MM``); the steps
            are spaced in that unit, then converted (the grid the CLI has always built).
    """
    centre = np.mean(list(campaign.locations.values()), axis=0)
    steps = (np.linspace(-half_width, half_width, per_side) * unit if per_side > 1
             else np.zeros(1))
    return np.array([centre + [dx, dy, dz] for dz in heights for dx in steps for dy in steps])


def plan(cal: Calibration, campaign: Campaign, *, grid: np.ndarray | None = None,
         n_postures: int = 40, families: str = "auto", seed: int = 0,
         sigma_location: float | None = None, progress: bool = False) -> Plan:
    """Rank candidate SPATs by how much they would shrink the worst-axis map uncertainty.

    Args:
        cal: a calibration of the ``proposed`` model.
        campaign: the campaign it was identified from.
        grid: candidate R-Test nest positions in the MT-CS, shape (k, 3), m; default: a 3 x 3 grid
            of 260 mm spacing around the present nests' centre, on their table and 250 mm above
            (:func:`candidate_grid`).
        n_postures: postures per candidate SPAT.
        families: ``"auto"`` (any posture, plus one family per worst angular range of the worst
            axes) or ``"any"``.
        seed: seed of the IK starts.
        sigma_location: prior std of a nest position per coordinate, m (default: the stated
            noise the calibration's fit used, else 3 um).
        progress: show the candidates evaluated (log lines when stderr is not a terminal).
    """
    check_plannable(campaign)
    if not cal.unknowns.map_axes:
        raise ValueError("cal: plan needs a calibration of the proposed model (with maps)")
    model, info = information_now(cal, campaign, sigma_location=sigma_location)
    u = model.u
    cov = np.linalg.inv(info)
    std_now = _map_std(np.diag(cov), u)
    estimated = [a for a in u.map_axes if cal.node_identifiable[a].any()]
    if not estimated:
        raise ValueError("cal: no axis has an identified map node; nothing to plan for")
    rms_now = {a: float(np.sqrt(np.mean(std_now[a] ** 2))) for a in u.map_axes}
    worst = max(estimated, key=lambda a: rms_now[a])
    nodes_deg = {a: np.degrees(u.start.map(a).nodes) for a in u.map_axes}
    ranges = {a: _worst_ranges(std_now[a], nodes_deg[a]) for a in estimated}
    length_grads = _length_grads(cal, campaign, u)
    length_now = _length_rms(length_grads, cov)

    if grid is None:
        grid = candidate_grid(campaign)
    arm = u.arm
    lim = arm.joint_limits
    fams: list[tuple[str, np.ndarray | None]] = [("any posture", None)]
    if families == "auto":
        for axis in sorted(ranges, key=lambda a: -rms_now[a])[:2]:
            for lo, hi, _ in ranges[axis]:
                box = lim.copy()
                a_lo, a_hi = np.degrees(lim[axis - 1])
                if lo > hi:  # wraps through 180 deg: keep the wider part within the limits
                    parts = [(max(-180.0, a_lo), hi), (lo, min(180.0, a_hi))]
                    lo, hi = max(parts, key=lambda p: p[1] - p[0])
                lo, hi = max(lo - 2.5, a_lo), min(hi + 2.5, a_hi)
                if hi <= lo:
                    continue
                box[axis - 1] = np.radians([lo, hi])
                fams.append((f"A{axis} in [{lo:g}, {hi:g}] deg", box))
    rng = np.random.default_rng(seed)
    conditions = planned_conditions(campaign)
    rot, t = cal.parameters.rotation(), cal.parameters.translation
    out = []
    cells = np.atleast_2d(grid)
    ticker = Progress("plan", "candidate", total=len(cells) * len(fams), enabled=progress)
    for p_mt in cells:
        target = np.tile(rot.T @ (p_mt - t), (n_postures, 1))
        for name, box in fams:
            ticker.update(1)
            try:
                q = stylus_ik(arm, cal.parameters, target, rng, starts=box, columns=conditions)
            except Exception:  # unreachable with this family: not a candidate
                continue
            new_info = model.add(info, held_columns(arm, q, conditions))
            new_cov = np.linalg.inv(new_info)
            std_after = _map_std(np.diag(new_cov), u)
            rms_after = {a: float(np.sqrt(np.mean(std_after[a] ** 2))) for a in u.map_axes}
            out.append(Candidate(np.asarray(p_mt, dtype=float), name, box, q, rms_after,
                                 rms_after[worst], _length_rms(length_grads, new_cov)))
    ticker.close()
    out.sort(key=lambda c: c.worst_after)
    n_points = 0 if campaign.points is None else len(campaign.points.group)
    return Plan(worst, rms_now, ranges, length_now, out, n_points)


def _length_grads(cal: Calibration, campaign: Campaign, u: Unknowns) -> np.ndarray | None:
    """Gradients of the bar length errors w.r.t. the full layout, shape (k, P), or None."""
    log = campaign.lengthbar
    if log is None or not campaign.bar:
        return None
    pairs = bar_pairs(campaign)
    bar = u.with_samples(Samples.of_log(u.arm, log))  # the bar's own columns (temp_c, ...)
    pos, jac = bar.jacobian(u.full_vector(cal.parameters), log.q)
    _, unit = pair_errors(pos, pairs)
    return np.array([jac.rmatmul(w) for w in pair_weights(pairs, unit, len(log.q))])


def _length_rms(grads: np.ndarray | None, cov: np.ndarray) -> float | None:
    if grads is None:
        return None
    return float(np.sqrt(np.mean(np.einsum("ij,jk,ik->i", grads, cov, grads))))


def map_uncertainty(cal: Calibration, campaign: Campaign) -> dict[int, float]:
    """Return the RMS node std per mapped axis of a calibration under the plan's model, rad."""
    model, info = information_now(cal, campaign)
    std = _map_std(np.diag(np.linalg.inv(info)), model.u)
    return {a: float(np.sqrt(np.mean(s ** 2))) for a, s in std.items()}


def _location(cal: Calibration, given: float | None) -> float:
    """Return the nest positions' prior std: ``given``, else the fit's stated one, m."""
    if given is not None:
        return given
    return cal.stated_noise.location if cal.stated_noise is not None else SIGMA_LOCATION
