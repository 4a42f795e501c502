r"""Identification of the arm from SPATs with the R-Test (paper Section 3.2, Eq. 3-6).

Unknowns: X0 (r-CS -> MT-CS rotation), the DH errors, the tool vector, and for the ``proposed``
model the encoder maps of the axes the data can see. Measured sphere position: R-Test zero position
plus R-Test displacement (Eq. 3); with ``use_rtest=False``, the location's mean displacement for
every sample (the conventional SPAT). Instead of differencing against a reference sample (Eq. 4, 6)
the translation between the frames is an unknown too: it removes the reference sample's noise from
every residual.

SciPy's ``least_squares`` minimises the residuals with the analytic, sparse Jacobian of
:class:`aacmm_pin.fit.unknowns.Unknowns`; see :mod:`aacmm_pin.fit.identifiability` for the rules on what the
data cannot determine.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.optimize import OptimizeResult
from scipy.special import chdtrc

from aacmm_pin._blas import single_threaded_blas
from aacmm_pin.data.campaign import Campaign, PointLog, SpatLog
from aacmm_pin.effects import Kind, Term
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.errors import AacmmError
from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit.robust import Outlier
from aacmm_pin.fit.solver import Factor, Nuisance, Problem, SolverSettings
from aacmm_pin.fit.unknowns import BlockJacobian, FrameKey, NestKey, NodeKey, UnknownKey, Unknowns
from aacmm_pin.model.arm import Arm, load_arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples
from aacmm_pin.progress import Progress
from aacmm_pin.units import (
    SIGMA_BAR,
    SIGMA_LOCATION,
    SIGMA_POINT,
    SIGMA_RTEST,
    SIGMA_SOCKET,
    SOCKET_PRIOR,
    STEP_DEG,
)

MODELS = ("dh", "proposed")
NESTS = ("auto", "estimate", "fixed")
"""How :func:`identify` treats the R-Test nests' offsets."""
NOISE_P = 1e-3
"""A residual whose chi-square p-value against the stated noise is below this does not match it."""
MIN_DOF_FRACTION = 0.1
"""An identification whose degrees of freedom are fewer than this fraction of its residual
coordinates reports ``success`` False: its residual cannot estimate the noise."""
MAX_FIT_RMS = 0.2e-3
"""A fit of R-Test SPATs whose RMS residual exceeds this (m) reports ``success`` False: no
articulated arm CMM leaves that after calibration, so the inputs disagree (units, R-Test zero
positions, readouts). Fits of absolute points alone (robots on a laser tracker: a DH model leaves
1 mm on real UR5 and WAM data) are not judged by it."""
BAR_ID = 100_000
"""A length-bar socket used as a nest has id ``BAR_ID * placement + socket index`` (sorted names)."""


class IdentificationError(AacmmError):
    """The campaign cannot be identified (too few locations, no motion, non-finite values)."""


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`identify`: the calibrated parameters and how well they are known."""

    parameters: Parameters
    """Identified parameters (held entries at their start values)."""
    model: str
    """``"dh"`` or ``"proposed"``."""
    use_rtest: bool
    """Whether each sample's R-Test displacement was used (else each location's mean)."""
    names: list[str]
    """Names of the estimated entries, in the order of ``x`` and ``covariance``."""
    x: np.ndarray
    """Estimated values, shape (n,), SI."""
    covariance: np.ndarray
    """Linearised covariance of ``x``, shape (n, n), SI (sigma from ``sigma``)."""
    sigma: float
    """Noise standard deviation per coordinate used for the covariance, m (with per-point
    ``sigma_um``: that of a point whose stated noise is the median, the others scaled by theirs)."""
    fun: np.ndarray
    """Residuals predicted - measured, shape (N, 3), m."""
    location: np.ndarray
    """R-Test location of each residual row, shape (N,)."""
    success: bool
    """Whether the solver converged."""
    status: int
    """Solver status (scipy's meaning)."""
    message: str
    """Solver message, or why the identification failed."""
    nfev: int
    """Number of residual evaluations."""
    unidentifiable: list[str]
    """Plain-language list of what the data does not determine and how it was handled."""
    node_identifiable: dict[int, np.ndarray]
    """Axis -> mask of identified map nodes, shape (n_nodes,)."""
    runtime_s: float
    """Wall-clock time of the identification, s."""
    raw: OptimizeResult = field(repr=False)
    """The final raw scipy result."""
    unknowns: Unknowns = field(repr=False)
    """The final layout (free entries, start values)."""
    constraints: sp.csr_matrix = field(repr=False)
    """Rows C over the free arm entries held as ``C @ (x - x_start) = 0`` (gauges, held directions)."""
    identifiable: np.ndarray = field(repr=False)
    """Per free arm entry (``unknowns.names``): whether the data determines it."""
    q: np.ndarray = field(repr=False)
    """The SPAT readouts used, shape (N, n_axes), rad."""
    problem: Problem = field(repr=False)
    """The solved least-squares problem (structure and preconditioner), for :func:`refit`."""
    settings: SolverSettings = field(repr=False)
    """Solver settings (loss, f_scale, max_nfev) for :func:`refit`."""
    nuisance_keys: tuple[UnknownKey, ...] = ()
    """What each entry of ``x`` after the arm's is: nest offsets, then instrument frames."""
    inputs: tuple[str, ...] = ("spat",)
    """The measurement kinds fitted: ``"spat"``, ``"points"``, ``"bar"`` (the length bar)."""
    nests: str = ""
    """How the R-Test nests' offsets were treated (estimated or fixed) and why; empty without."""
    robust: bool = False
    """Whether outliers were rejected (``identify(..., robust=True)``, :mod:`aacmm_pin.fit.robust`)."""
    outliers: tuple[Outlier, ...] = ()
    """Samples the robust fit rejected (weight 0), largest first; empty without ``robust``."""
    suspects: tuple[Outlier, ...] = ()
    """Without ``robust``: samples beyond ``robust.OUTLIER_K`` robust sigmas, kept in the fit
    (named in ``message`` too)."""
    inlier: np.ndarray | None = field(default=None, repr=False)
    """Samples kept in the fit, shape (N,), bool; None: all."""

    def equivalent(self, other: Parameters) -> tuple[Parameters, float]:
        """Return ``other`` (e.g. the truth) moved into this calibration's gauge and held values.

        See :func:`aacmm_pin.fit.identifiability.equivalent_vector`. Returns the parameters and the RMS
        change of the predictions on the campaign's postures (m).
        """
        full = self.unknowns.with_free(np.ones_like(self.unknowns.free))
        _, jac = full.jacobian(full.full_vector(self.parameters), self.q)
        vec, rms = ident.equivalent_vector(self.unknowns, jac.sparse(), self.constraints,
                                           full.full_vector(other))
        return full.parameters(vec), rms

    @property
    def keys(self) -> list[UnknownKey]:
        """What each entry of ``x`` is (typed; ``names`` are their strings), in order."""
        return [*self.unknowns.keys, *self.nuisance_keys]

    @property
    def std(self) -> dict[str, float]:
        """Standard uncertainty (k=1) of every estimated entry by name, SI."""
        return dict(zip(self.names, np.sqrt(np.clip(np.diag(self.covariance), 0, None))))

    def node_std(self, axis: int) -> np.ndarray:
        """Standard uncertainty of each node of a map (rad), NaN where not identified."""
        std = dict(zip(self.keys, np.sqrt(np.clip(np.diag(self.covariance), 0, None))))
        return np.array([std.get(NodeKey.at(axis, node), np.nan)
                         for node in np.degrees(self.parameters.map(axis).nodes)])

    @property
    def n_determined(self) -> int:
        """Number of arm parameter directions the data determines (unknowns less held rows)."""
        return int(len(self.unknowns.names) - self.constraints.shape[0])

    @property
    def fit_rms(self) -> float:
        """RMS of the residual coordinates of the samples kept (all but :attr:`outliers`), m."""
        kept = self.fun if self.inlier is None else self.fun[self.inlier]
        return float(np.sqrt(np.mean(kept ** 2)))

    @property
    def accuracy(self) -> float:
        """Accuracy per coordinate the calibration claims, m.

        :attr:`sigma` (the fit RMS with the dof of the determined parameters removed, or the stated
        noise), at least :attr:`fit_rms`: what :func:`aacmm_pin.validate` compares the bar
        readouts' socket scatter with.
        """
        return max(self.sigma, self.fit_rms)

    def fit_rms_by_location(self) -> dict[int, float]:
        """RMS of the residual coordinates per R-Test location (samples kept), m."""
        keep = np.ones(len(self.fun), bool) if self.inlier is None else self.inlier
        return {int(m): float(np.sqrt(np.mean(self.fun[(self.location == m) & keep] ** 2)))
                for m in np.unique(self.location[keep])}

    def group_label(self, group: int) -> str:
        """Return the name of a group id of :attr:`location`.

        ``"2"`` for R-Test location 2 (or points group 2 alone), ``"bar3A"`` for a bar socket,
        ``"group 2"`` for points of group 2 beside SPATs.
        """
        labels = {k.location: k.label for k in self.nuisance_keys
                  if isinstance(k, NestKey) and k.label}
        return labels.get(group, f"group {-group}" if group < 0 else str(group))

    def nest_offsets_um(self) -> dict[str, list[float]]:
        """Return the estimated offset of every R-Test nest from its measured zero position, um.

        Location -> [dx, dy, dz] in the MT-CS; empty when the nests were held at their measured
        positions. The measured centres plus these offsets are what the fit's residual is against.
        """
        n_arm = len(self.unknowns.names)
        out: dict[str, list[float]] = {}
        for key, value in zip(self.nuisance_keys, self.x[n_arm:]):
            if isinstance(key, NestKey) and not key.label:
                out.setdefault(str(key.location), []).append(float(value) * 1e6)
        return out

    def report(self) -> dict[str, Any]:
        """Return the ``report.json`` content."""
        return {
            "model": self.model, "use_rtest": self.use_rtest, "inputs": list(self.inputs),
            "nests": self.nests,
            "n_samples": int(len(self.fun)),
            "n_parameters": self.n_determined, "n_unknowns": int(len(self.x)),
            "fit_rms_um": self.fit_rms * 1e6,
            "fit_rms_um_by_location": {self.group_label(k): v * 1e6 for k, v in
                                       self.fit_rms_by_location().items()},
            "sigma_um": self.sigma * 1e6, "runtime_s": self.runtime_s, "success": self.success,
            "status": self.status, "message": self.message, "nfev": self.nfev,
            "unidentifiable": list(self.unidentifiable),
            "std": {n: float(s) for n, s in self.std.items()},
            "nest_offsets_um": self.nest_offsets_um(),
            "robust": self.robust,
            "outliers": [o.to_dict() for o in self.outliers],
            "suspects": [o.to_dict() for o in self.suspects],
        }


def measured_positions(campaign: Campaign, use_rtest: bool = True) -> np.ndarray:
    """Return the measured sphere centres in the MT-CS (Eq. 3), shape (N, 3), m."""
    spat = campaign.spat
    assert spat is not None
    disp = spat.displacement.copy()
    if not use_rtest:
        for m in np.unique(spat.location):
            sel = spat.location == m
            disp[sel] = disp[sel].mean(axis=0)
    measured: np.ndarray = np.array([campaign.locations[int(m)] for m in spat.location]) + disp
    return measured


def check_campaign(campaign: Campaign, arm: Arm) -> SpatLog:
    """Return the campaign's SPAT log, or raise IdentificationError if it cannot be identified."""
    spat = campaign.spat
    if spat is None or len(spat.location) == 0:
        raise IdentificationError("the campaign has no SPAT samples (spat.csv)")
    if spat.q.shape[1] != arm.n_axes:
        raise IdentificationError(f"the campaign has {spat.q.shape[1]} axes, the arm "
                                  f"{arm.n_axes} ({arm.source})")
    bad = [name for name, arr in (("readouts", spat.q), ("displacements", spat.displacement),
                                  ("locations", np.array(list(campaign.locations.values()))))
           if not np.all(np.isfinite(arr))]
    if bad:
        raise IdentificationError(f"non-finite values (NaN or inf) in the {', '.join(bad)}")
    ids = np.unique(spat.location)
    if ids.size < 2:
        raise IdentificationError(
            f"the campaign has one R-Test location ({ids[0]}): SPATs at a single point cannot fix "
            "the arm's scale or its orientation in the MT-CS; measure at 2 or more locations "
            "(the paper uses 4)")
    for m in ids:
        q = spat.q[spat.location == m]
        if np.ptp(q, axis=0).max() < 1e-6:
            raise IdentificationError(
                f"all {len(q)} postures at location {m} are identical: a SPAT needs the arm moved "
                "through many postures with the stylus in the nest")
    return spat


def check_points(campaign: Campaign, arm: Arm) -> PointLog:
    """Return the campaign's absolute points, or raise IdentificationError if they cannot be used.

    Every instrument frame (``group``) is identified with the arm: one as X0 and the translation
    (without SPAT), the others with six unknowns each; each group's points must span 3-D space.
    """
    points = campaign.points
    if points is None or len(points.group) == 0:
        raise IdentificationError("the campaign has no absolute points (points.csv)")
    if points.q.shape[1] != arm.n_axes:
        raise IdentificationError(f"the campaign has {points.q.shape[1]} axes, the arm "
                                  f"{arm.n_axes} ({arm.source})")
    if not (np.all(np.isfinite(points.q)) and np.all(np.isfinite(points.point))):
        raise IdentificationError("non-finite values (NaN or inf) in the points or readouts")
    _check_point_tools(points, arm, "points.csv" if campaign.source is None
                       else str(campaign.source / "points.csv"))
    for g in np.unique(points.group):
        pts = points.point[points.group == g]
        if len(pts) < 4 or np.linalg.matrix_rank(pts - pts.mean(axis=0), tol=1e-4) < 3:
            raise IdentificationError(
                f"the measured points of group {g} ({len(pts)} points) lie on a line or a plane: "
                "they cannot fix that instrument's frame (measure 4 or more poses spread in 3-D)")
    return points


def _check_point_tools(points: PointLog, arm: Arm, path: str) -> None:
    """Raise IdentificationError if the points' tools are missing (several tools) or unknown."""
    listing = ", ".join(arm.tool_names)
    if points.tool is None:
        if arm.n_tools > 1:
            raise IdentificationError(f"{path}: line 1: column 'tool': missing; the arm has "
                                      f"{arm.n_tools} tools ({listing}): say which one each point "
                                      "measures")
        return
    known = set(arm.tool_names) | set(arm.tool_joints)
    bad = [k for k, name in enumerate(points.tool.tolist()) if name not in known]
    if bad:
        k = bad[0]
        line = f"line {points.lines[k]}" if points.lines is not None else f"row {k + 1}"
        raise IdentificationError(f"{path}: {line}: column 'tool': unknown tool "
                                  f"'{points.tool[k]}' ({len(bad)} such points); the arm's tools: "
                                  f"{listing}")


class Measurements(NamedTuple):
    """What an identification fits: one row per sample (SPAT, points, length-bar readouts)."""

    q: np.ndarray
    """Readouts, shape (N, n), rad."""
    measured: np.ndarray
    """Measured points, shape (N, 3), m: sphere centres in the MT-CS, tool points in their
    instrument frame; NaN for length-bar readouts (their socket's position is estimated)."""
    group: np.ndarray
    """R-Test location, instrument group or bar socket of each sample, shape (N,) (named by
    :meth:`Calibration.group_label`)."""
    samples: Samples
    """What effects depend on, per sample."""
    sigma: np.ndarray | None
    """Stated noise of each sample per coordinate, shape (N,), m (NaN: the R-Test's), or None."""
    nest: np.ndarray | None = None
    """Nest index of every sample (-1: none), shape (N,); None: no nests."""
    nest_sigma: np.ndarray = np.zeros(0)
    """Prior standard deviation of each nest's position per coordinate, shape (n_nests,), m."""
    nest_keys: tuple[tuple[int, str], ...] = ()
    """(id, label) of each nest: R-Test location m is (m, ""), a bar socket (id, "bar3A")."""
    frame: np.ndarray | None = None
    """Instrument frame index of every sample (-1: the main frame), shape (N,), or None."""
    frame_groups: tuple[int, ...] = ()
    """Instrument group of each frame besides the main one."""
    lengths: np.ndarray = np.zeros((0, 3))
    """Length rows (nest a, nest b, calibrated distance m), shape (n, 3)."""


def _spat_part(campaign: Campaign, arm: Arm, use_rtest: bool) -> Measurements:
    spat = check_campaign(campaign, arm)
    ids = np.unique(spat.location)
    return Measurements(spat.q, measured_positions(campaign, use_rtest), spat.location,
                        Samples.of_spat(arm, spat), None, np.searchsorted(ids, spat.location),
                        np.zeros(ids.size), tuple((int(m), "") for m in ids))


def _bar_part(campaign: Campaign, arm: Arm) -> Measurements:
    """The bar readouts: one nest per (placement, socket), lengths between a placement's sockets."""
    log = campaign.lengthbar
    if log is None or not campaign.bar:
        raise IdentificationError("--use-bar: the campaign has no length-bar data (lengthbar.csv "
                                  "and bar.csv)")
    if log.q.shape[1] != arm.n_axes or not np.all(np.isfinite(log.q)):
        raise IdentificationError("the length-bar readouts do not match the arm's axes or are not "
                                  "finite")
    sockets = sorted({str(s) for s in log.socket})
    keys = list(dict.fromkeys((int(p), str(s)) for p, s in zip(log.placement, log.socket)))
    index = {k: i for i, k in enumerate(keys)}
    nest = np.array([index[(int(p), str(s))] for p, s in zip(log.placement, log.socket)])
    ids = np.array([BAR_ID * p + sockets.index(s) for p, s in keys])
    lengths = [(index[(p, a)], index[(p, b)], length) for (a, b), length in campaign.bar.items()
               for p in dict.fromkeys(int(v) for v in log.placement)
               if (p, a) in index and (p, b) in index]
    sigma = campaign.noise.socket if campaign.noise else SIGMA_SOCKET
    return Measurements(log.q, np.full((len(nest), 3), np.nan), ids[nest],
                        Samples.of_log(arm, log), np.full(len(nest), sigma), nest,
                        np.full(len(keys), SOCKET_PRIOR),
                        tuple((int(i), f"bar{p}{s}") for i, (p, s) in zip(ids, keys)),
                        lengths=np.array(lengths, dtype=float).reshape(-1, 3))


def _join(parts: list[Measurements], arm: Arm) -> Measurements:
    """One measurement set of several kinds: rows stacked, nests and frames renumbered."""
    n = [len(p.q) for p in parts]
    nest, lengths, offset = [], [], 0
    for p in parts:
        nest.append(np.full(len(p.q), -1) if p.nest is None else
                    np.where(p.nest >= 0, p.nest + offset, -1))
        lengths.append(p.lengths + [offset, offset, 0.0])
        offset += p.nest_sigma.size
    frame, frames, f_off = [], [], 0
    for p in parts:
        frame.append(np.full(len(p.q), -1) if p.frame is None else
                     np.where(p.frame >= 0, p.frame + f_off, -1))
        frames += list(p.frame_groups)
        f_off += len(p.frame_groups)
    # stated noise: the R-Test's (NaN, set by identify) for SPAT, the default for points without
    sigma = np.concatenate([p.sigma if p.sigma is not None else
                            np.full(k, np.nan if p.nest is not None else SIGMA_POINT)
                            for k, p in zip(n, parts)])
    q = np.concatenate([p.q for p in parts])
    return Measurements(q, np.concatenate([p.measured for p in parts]),
                        np.concatenate([p.group for p in parts]),
                        Samples.concatenate([p.samples for p in parts]), sigma, np.concatenate(nest),
                        np.concatenate([p.nest_sigma for p in parts]),
                        tuple(k for p in parts for k in p.nest_keys), np.concatenate(frame),
                        tuple(frames), np.concatenate(lengths))


def measurements(campaign: Campaign, arm: Arm, use_rtest: bool, use_bar: bool = False
                 ) -> Measurements:
    """Return what an identification of ``campaign`` fits (checked; see :class:`Measurements`).

    SPAT: the measured sphere centres (Eq. 3), the R-Test locations, whose nest offsets are
    estimated. Points: the measured tool points and their instrument group; without SPAT the
    first group's frame is the main one (X0 and translation), every other group has a frame of
    its own. ``use_bar``: the length-bar readouts too, each socket a nest whose position is
    estimated, the calibrated distances between a placement's sockets as length rows.
    """
    parts = []
    if campaign.spat is not None or campaign.points is None:
        parts.append(_spat_part(campaign, arm, use_rtest))
    if campaign.points is not None:
        points = check_points(campaign, arm)
        ids = np.unique(points.group)
        own = ids if parts else ids[1:]  # groups with a frame of their own
        frame = np.where(np.isin(points.group, own), np.searchsorted(own, points.group), -1)
        parts.append(Measurements(points.q, points.point, points.group if not parts
                                  else -points.group, Samples.of_log(arm, points),
                                  points.sigma, frame=frame if own.size else None,
                                  frame_groups=tuple(int(g) for g in own)))
    if use_bar:
        parts.append(_bar_part(campaign, arm))
    if len(parts) == 1 and not use_bar:
        part = parts[0]
        if part.frame is None and part.nest is not None:  # SPAT alone: as before
            return part._replace(sigma=None)
        return part
    return _join(parts, arm)


def _kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return R (3, 3), t (3,) minimising |R a + t - b| over point pairs a, b (N, 3)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((b - cb).T @ (a - ca))
    rot = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    return rot, cb - rot @ ca


def _initial_frame(arm: Arm, start: Parameters, q: np.ndarray, measured: np.ndarray,
                   group: np.ndarray, tool: np.ndarray | None) -> Parameters:
    """Return start parameters with X0 and translation from a Kabsch fit of the group centres.

    ``tool``: the tool index of every sample, shape (N,), or None (the arm's only tool).
    """
    ids = np.unique(group)
    pred = stylus_positions(arm, start, q, frame="r", tool=tool)
    if ids.size > 1:
        p_r = np.array([pred[group == m].mean(axis=0) for m in ids])
        p_mt = np.array([measured[group == m].mean(axis=0) for m in ids])
    else:  # one group of absolute points: every point
        p_r, p_mt = pred, measured
    a = p_r - p_r.mean(axis=0)
    if len(p_r) < 3 or np.linalg.matrix_rank(a, tol=1e-3) < 2:
        return start.replace(translation=p_mt.mean(axis=0) - p_r.mean(axis=0))
    rot, trans = _kabsch(p_r, p_mt)  # maps r-CS to MT-CS
    # rot = Ry(beta) Rx(alpha) Rz(gamma): row 1 is (ca sg, ca cg, -sa)
    alpha = np.arctan2(-rot[1, 2], np.hypot(rot[1, 0], rot[1, 1]))
    gamma = np.arctan2(rot[1, 0], rot[1, 1])
    beta = np.arctan2(rot[0, 2], rot[2, 2])
    return start.replace(rotation_abc=[alpha, beta, gamma], translation=trans)


def _without_rtest_nests(meas: Measurements) -> Measurements:
    """Return the measurements with the R-Test nests held at their measured positions.

    The R-Test locations' offsets are no longer unknowns (their samples keep their measured zero
    positions); other nests (length-bar sockets, whose positions are unknown) stay.
    """
    if meas.nest is None:
        return meas
    keep = meas.nest_sigma > 0  # R-Test nests carry 0: their prior is sigma_location
    index = np.cumsum(keep) - 1
    nest = np.where((meas.nest >= 0) & keep[np.maximum(meas.nest, 0)], index[meas.nest], -1)
    lengths = meas.lengths.copy()
    lengths[:, :2] = index[lengths[:, :2].astype(int)]
    return meas._replace(nest=nest if keep.any() else None, nest_sigma=meas.nest_sigma[keep],
                         nest_keys=tuple(k for k, on in zip(meas.nest_keys, keep) if on),
                         lengths=lengths)


def _nuisance(arm: Arm, start: Parameters, meas: Measurements, sigma_class: float,
              sigma_location: float) -> tuple[Nuisance, np.ndarray, list[UnknownKey]]:
    """Return the problem's nests, frames and lengths, measured points and nuisance keys.

    The measured points are completed with the bar sockets' start positions (the mean of their
    readouts' start-model points); the frames start from a Kabsch fit to the start model.
    """
    measured = meas.measured.copy()
    socket = np.isnan(measured[:, 0])
    frame_start = np.zeros((len(meas.frame_groups), 3, 4))
    if socket.any() or meas.frame_groups:
        pred = stylus_positions(arm, start, meas.q, frame="mt", samples=meas.samples)
        if meas.nest is not None:  # sockets are nests
            for j in np.unique(meas.nest[socket]):
                rows = meas.nest == j
                measured[rows] = pred[rows].mean(axis=0)
        if meas.frame is not None:  # frame_groups come with a frame per sample
            for f in range(len(meas.frame_groups)):
                rows = meas.frame == f
                rot, trans = _kabsch(measured[rows], pred[rows])
                frame_start[f] = np.column_stack([rot, trans])
    nest_sigma = np.where(meas.nest_sigma > 0, meas.nest_sigma, sigma_location)
    keys: list[UnknownKey] = [NestKey(m, c, label) for m, label in meas.nest_keys for c in "xyz"]
    keys += [FrameKey(g, c) for g in meas.frame_groups for c in ("rx", "ry", "rz", "tx", "ty", "tz")]
    nuisance = Nuisance(nest=meas.nest, nest_sigma=nest_sigma, frame=meas.frame,
                        frame_start=frame_start, lengths=meas.lengths,
                        length_weight=sigma_class / SIGMA_BAR)
    return nuisance, measured, keys


def identify(campaign: Campaign, arm: Arm | None = None, model: str = "proposed",
             use_rtest: bool = True, *, start: Parameters | None = None, step_deg: float = STEP_DEG,
             map_axes: tuple[int, ...] | None = None, loss: str = "linear",
             f_scale: float | None = None, sigma: float | None = None,
             sigma_location: float = SIGMA_LOCATION, max_nfev: int = 200, jac: str = "analytic",
             progress: bool = False, extensions: tuple[Term, ...] = (),
             use_bar: bool = False, robust: bool = False, nests: str = "auto") -> Calibration:
    """Identify the arm's parameters from the SPATs of a campaign.

    Args:
        campaign: campaign with SPAT samples and R-Test zero positions, or (without SPAT) with
            absolute tool points (``points.csv``, one instrument frame identified as X0 and the
            translation; no nest offsets).
        arm: the arm (default: the embedded default arm).
        model: ``"dh"`` (X0, DH errors, tool) or ``"proposed"`` (also the encoder maps).
        use_rtest: use each sample's R-Test displacement (True) or each location's mean (False).
        start: start values (default: the URDF's nominal values; X0 and translation from a fit of
            the location centres).
        step_deg: map node step, deg.
        map_axes: axes whose maps are estimated (default: all, for ``proposed``).
        loss: scipy loss of every solve, e.g. ``"linear"`` (default). For outliers use ``robust``:
            scipy's ``"soft_l1"`` / ``"huber"`` weigh coordinates, not samples, with a fixed
            scale, and do not reach their tolerance on these problems.
        f_scale: residual scale of a scipy robust loss, m (default 3 x sigma).
        sigma: R-Test noise per coordinate, m; None estimates it from the residuals.
        sigma_location: standard uncertainty of each R-Test zero position per coordinate, m
            (paper Section 5: 3 um); each nest's offset is estimated with this prior.
        max_nfev: most residual evaluations per solve, a cap well above what a solve needs to
            reach its tolerance (``nfev`` reports what was used; not converged within it:
            ``success`` False).
        jac: ``"analytic"`` (Pinocchio, sparse in the map nodes) or a scipy finite-difference
            scheme (``"2-point"``, ``"3-point"``) on the same problem, for comparison.
        progress: show progress (evaluations and residual RMS; log lines when stderr is not a
            terminal).
        extensions: further terms of the effect library (:mod:`aacmm_pin.effects`) to estimate
            (angle, scale or measurement kind; map terms are ``map_axes``).
        nests: the R-Test nests' offsets: ``"estimate"`` (each with the prior
            ``sigma_location``), ``"fixed"`` (held at the measured positions) or ``"auto"``:
            estimated only when the model's residual matches the stated R-Test noise (chi-square,
            p >= 0.001; ``sigma`` or 2 um), else fixed, since the offsets of an incomplete model
            take up its error (the choice and why are in :attr:`Calibration.nests`).
        use_bar: fit the length-bar readouts too (a calibration input, not only a check): every
            socket's position is estimated from its readouts and the calibrated distances
            between a placement's sockets are residuals (stated noise per readout coordinate:
            ``campaign.json``'s socket, else ``units.SIGMA_SOCKET``; ``units.SIGMA_BAR`` per
            length).
        robust: reject outliers (:mod:`aacmm_pin.fit.robust`): iteratively reweighted least squares,
            Huber then hard rejection of every sample (its three coordinates together) whose
            whitened residual norm exceeds ``robust.OUTLIER_K`` robust sigmas; they are listed in
            ``outliers`` and left out of the final fit, its noise and its covariance. Without
            it, such samples are listed in ``suspects`` and named in ``message`` (``success``
            stays the solver's: the DH model on an arm with encoder errors has such residuals on
            clean data, and they are not a failure to converge).

    Returns:
        The calibration; ``success`` is False (with a message) when the solver did not converge
        or the robust fit's outlier set did not settle.

    Raises:
        IdentificationError: for campaigns that cannot be identified.
        ValueError: for an unknown ``model``, or a ``sigma`` / ``sigma_location`` not > 0.
    """
    if jac not in ("analytic", "2-point", "3-point", "cs"):
        raise ValueError(f"jac: choose 'analytic', '2-point' or '3-point', got {jac!r}")
    if model not in MODELS:
        raise ValueError(f"model: choose from {', '.join(MODELS)}, got {model!r}")
    for name, value in (("sigma", sigma), ("sigma_location", sigma_location)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}: a positive noise in m expected, got {value!r}")
    if nests not in NESTS:
        raise ValueError(f"nests: choose from {', '.join(NESTS)}, got {nests!r}")
    arm = arm or load_arm()

    def fit(fixed: bool) -> Calibration:
        return _identify(campaign, arm, model, use_rtest, start, step_deg, map_axes, loss, f_scale,
                         sigma, sigma_location, max_nfev, jac, progress, extensions, use_bar, robust,
                         fixed)

    with single_threaded_blas():  # products of a few hundred columns: BLAS threads only spin
        cal = fit(nests == "fixed")
        rtest_nests = "spat" in cal.inputs
        if not rtest_nests:
            return cal
        if nests != "auto":
            return replace(cal, nests=f"{nests} (asked)")
        p_value, ratio = _noise_consistency(cal, sigma or SIGMA_RTEST)
        if p_value >= NOISE_P:
            return replace(cal, nests=f"estimated: the fit's residual matches the stated R-Test "
                                      f"noise (RMS {ratio:.2f} x, p = {p_value:.2g})")
        fixed = fit(True)
        return replace(fixed, nests=(
            f"fixed at their measured positions: the model's residual is {ratio:.1f} x the stated "
            f"R-Test noise (p = {p_value:.2g}), so nest offsets estimated with it would take up "
            "model error"))


def _noise_consistency(cal: Calibration, stated: float) -> tuple[float, float]:
    """Return the chi-square p-value of the residual against the stated noise, and RMS/noise.

    ``stated``: the R-Test noise per coordinate, m; other kinds (points, bar sockets) count with
    their own stated noise relative to it (the row weights). Degrees of freedom: the residual
    coordinates less the determined parameters.
    """
    res = cal.fun.ravel() / stated
    if cal.problem.row_weight is not None:  # weight = (the solve's sigma) / (the row's noise)
        res = res * cal.problem.row_weight * stated / cal.problem.sigma_class
    if cal.inlier is not None:  # rejected outliers are not the model's residual
        res = res[np.repeat(cal.inlier, 3)]
    dof = max(res.size - cal.n_determined, 1)
    stat = float(np.sum(res ** 2))
    return float(chdtrc(dof, stat)), float(np.sqrt(stat / res.size))  # = scipy.stats.chi2.sf


def _identify(campaign: Campaign, arm: Arm, model: str, use_rtest: bool, start: Parameters | None,
              step_deg: float, map_axes: tuple[int, ...] | None, loss: str, f_scale: float | None,
              sigma: float | None, sigma_location: float, max_nfev: int, jac: str, progress: bool,
              extensions: tuple[Term, ...], use_bar: bool, robust: bool,
              fixed_nests: bool) -> Calibration:
    tic = time.perf_counter()
    meas = measurements(campaign, arm, use_rtest, use_bar)
    if fixed_nests:
        meas = _without_rtest_nests(meas)
    q, group, samples, stated = meas.q, meas.group, meas.samples, meas.sigma
    main = ~np.isnan(meas.measured[:, 0]) & (True if meas.frame is None else meas.frame < 0)
    start = start or _initial_frame(arm, Parameters.nominal(arm, step_deg), q[main],
                                    meas.measured[main], group[main],
                                    None if samples.tool is None else samples.tool[main])
    axes = tuple(range(1, arm.n_axes + 1)) if map_axes is None else tuple(map_axes)
    full_u = Unknowns.full(arm, start, axes if model == "proposed" else (),
                           tuple(t for t in extensions if t.kind is not Kind.MAP), samples)
    has_spat = campaign.spat is not None or campaign.points is None
    sigma_class = sigma or (SIGMA_RTEST if has_spat else SIGMA_POINT if stated is None
                            else float(np.median(stated)))
    if stated is not None:  # SPAT rows of a joint problem: the R-Test's noise
        stated = np.where(np.isnan(stated), sigma_class, stated)
    nuisance, measured, nuisance_keys = _nuisance(arm, start, meas, sigma_class, sigma_location)
    n = len(q)
    base_w = np.ones(n) if stated is None else sigma_class / stated
    settings = SolverSettings(loss=loss, f_scale=f_scale or 3 * sigma_class, max_nfev=max_nfev)
    with Progress(f"identify {model}", "evaluation", enabled=progress) as bar:
        def evaluated(rms: float) -> None:
            bar.update(rms_um=rms * 1e6)

        def fit(keep: np.ndarray | None) -> _Fit:
            return _fit_rounds(full_u, start, q, measured, nuisance, sigma_class,
                               None if stated is None and keep is None else
                               base_w * (1.0 if keep is None else keep), keep, settings, jac,
                               evaluated)

        def reweight(f: _Fit, w: np.ndarray) -> _Fit:
            prob = Problem(f.unknowns, q, measured, nuisance, f.constraints, f.obs.scale,
                           f.problem.x_ref, f.x, sigma_class, base_w * np.sqrt(w))
            out = prob.solve(prob.z(f.x), settings, jac, on_evaluation=evaluated)
            return f._replace(problem=prob, res=out, x=prob.x(out.x), nfev=int(out.nfev),
                              jac=None)

        now = fit(None)
        inlier: np.ndarray | None = None
        settled = True
        if robust:
            # the first fit's Jacobian is not held through the refits
            inlier, settled, now = _robust(now._replace(jac=None), fit, reweight, base_w)
    unknowns, unvisited, gauges, obs, constraints = (now.unknowns, now.unvisited, now.gauges,
                                                     now.obs, now.constraints)
    problem, res, x_full, nfev, jac_x = now.problem, now.res, now.x, now.nfev, now.jac
    now = now._replace(jac=None)
    x_arm = x_full[:problem.n_arm]
    n_det = problem.n_arm - obs.hold.shape[0] - len(gauges) + problem.n_frame
    kept = np.ones(n, bool) if inlier is None else inlier
    dof_fraction = max(3 * int(kept.sum()) + problem.n_lengths - n_det, 1) / (3 * int(kept.sum()))
    residual = problem.data_residuals(x_full)
    norms = rob.whitened_norms(residual, base_w)
    scale = rob.robust_scale(norms, dof_fraction)  # as the IRLS judged: median over all samples
    flagged = rob.describe(residual, norms, scale, ~kept if robust else rob.flag(norms, scale),
                           rob.sample_sources(campaign, use_bar))
    data_res = res.fun[:3 * n][np.repeat(kept, 3)]  # weighted: the noise in units of sigma_class
    dof = data_res.size + problem.n_lengths - n_det
    enough = dof >= MIN_DOF_FRACTION * data_res.size
    # too few residuals: the residual says nothing about the noise; the stated noise stands
    sig = _sigma(data_res, n_det, sigma) if enough else float(sigma or sigma_class)
    covariance = problem.covariance(x_full, sig, jac_x)
    del jac_x
    names = unknowns.names + [str(k) for k in nuisance_keys]
    params = unknowns.parameters(x_arm)
    lines = ident.describe(unknowns, unvisited, obs)
    if gauges:
        lines.append("map constants: " + ", ".join(f"A{a}" for a in gauges) + " maps have zero "
                     "mean over their free nodes; a constant encoder error is indistinguishable "
                     "from the axis offset (dth), gamma0 (A1), the tool (A7) or DH errors, which "
                     "carry it")
    identifiable = np.zeros_like(unvisited)
    identifiable[np.flatnonzero(unknowns.free)] = obs.identifiable
    final_u = unknowns
    node_ok = {a: identifiable[final_u.map_slice(a)].copy() for a in final_u.map_axes}
    success = bool(res.success)  # the last round's: earlier ones only set the held directions
    message = res.message if success else f"did not converge: {res.message}"
    outliers = flagged if robust else ()
    suspects = () if robust else flagged
    limit = f"{rob.OUTLIER_K:g} robust sigmas ({rob.OUTLIER_K * scale * 1e6:.3g} um whitened norm)"
    if robust:
        message = (f"{message}; robust fit: {len(outliers)} outlier samples beyond {limit} "
                   f"rejected" + (_where(outliers) if outliers else ""))
        if not settled:
            success = False
            message += (f"; the outlier set still changed after {rob.MAX_REJECT_ITERATIONS} "
                        "refits (outliers and model errors of similar size?)")
    elif suspects:  # reported, not failed: a model that misses an effect has them on clean data
        message = (f"{message}; but {len(suspects)} samples lie beyond {limit}: outliers or a "
                   f"model that misses an effect{_where(suspects)}; refit with robust=True "
                   "(aacmm-pin identify --robust) to reject them")
    if not enough:
        more = int(np.ceil((n_det / (1 - MIN_DOF_FRACTION) - data_res.size) / 3))
        success = False
        message = (f"too few samples: {data_res.size} residual coordinates for {n_det} determined "
                   f"parameters ({dof} degrees of freedom, fewer than "
                   f"{MIN_DOF_FRACTION:.0%} of the residuals), so neither the noise nor the "
                   f"uncertainty can be estimated from the fit (the stated noise "
                   f"{sig * 1e6:.2g} um is used); measure at least about {more} more postures")
    rms = float(np.sqrt(np.mean(residual[kept] ** 2)))
    if enough and has_spat and rms > MAX_FIT_RMS:
        success = False
        message = (f"fit RMS {rms * 1e6:.4g} um is beyond {MAX_FIT_RMS * 1e6:.3g} um, more than "
                   "any articulated arm leaves after calibration: the inputs disagree (units of a "
                   "column, R-Test zero positions in locations.csv, readouts); " + message)
    return Calibration(parameters=params, model=model, use_rtest=use_rtest, names=names,
                       x=x_full, covariance=covariance, sigma=sig,
                       fun=residual, location=group.copy(), success=success,
                       status=int(res.status), message=str(message),
                       nfev=int(nfev), unidentifiable=lines, node_identifiable=node_ok,
                       runtime_s=time.perf_counter() - tic,
                       raw=OptimizeResult({k: v for k, v in res.items() if k != "jac"}),
                       unknowns=final_u,
                       constraints=constraints, identifiable=obs.identifiable, q=q,
                       problem=problem, settings=settings, nuisance_keys=tuple(nuisance_keys),
                       inputs=tuple(k for k, on in (("spat", has_spat),
                                                    ("points", campaign.points is not None),
                                                    ("bar", use_bar)) if on),
                       robust=robust, outliers=outliers, suspects=suspects, inlier=inlier)


def _where(flagged: tuple[Outlier, ...]) -> str:
    """Return ``" (largest: spat.csv line 12, 1000 um; ...)"`` for the first few flagged samples."""
    def one(o: Outlier) -> str:
        at = f"line {o.line}" if o.line is not None else f"row {o.row + 1}"
        return f"{o.file} {at}, {o.residual * 1e6:.4g} um"
    more = f"; {len(flagged) - 3} more" if len(flagged) > 3 else ""
    return f" (largest: {'; '.join(one(o) for o in flagged[:3])}{more})"


class _Fit(NamedTuple):
    """One least-squares identification: its structure, problem and solution."""

    unknowns: Unknowns
    unvisited: np.ndarray
    gauges: list[int]
    obs: ident.Observability
    constraints: sp.csr_matrix
    problem: Problem
    res: OptimizeResult
    x: np.ndarray
    nfev: int
    jac: BlockJacobian | None = None
    """The data Jacobian at ``x`` when the fit has it (for the covariance; then released)."""


def _fit_rounds(full_u: Unknowns, start: Parameters, q: np.ndarray, measured: np.ndarray,
                nuisance: Nuisance, sigma_class: float, weight: np.ndarray | None,
                keep: np.ndarray | None, settings: SolverSettings, jac: str,
                on_evaluation: Callable[[float], None]) -> _Fit:
    """Identify from the start values with the samples of ``keep`` (None: all).

    What the data can determine (unvisited nodes, gauges, held directions) is decided on the
    samples kept: unvisited nodes, gauges and held directions at the start; then the held
    directions are checked where one Gauss-Newton step from the start lands
    (:func:`_decision_point`, near the solution), before the solve, and at the solution. A check
    that holds another number of directions decides them again there (and solves again, up to 3
    solves); one that holds as many keeps them, so that the start's directions stand wherever the
    decision does not change.
    """
    rows = None if keep is None else np.repeat(keep.astype(float), 3)
    unvisited = ident.unvisited_nodes(full_u, q if keep is None else q[keep])
    unknowns = full_u.with_fixed(unvisited)
    n_arm = int(unknowns.free.sum())
    x_start = np.concatenate([unknowns.vector(start),
                              np.zeros(3 * nuisance.n_nests + 6 * nuisance.n_frames)])

    def jacobian(x: np.ndarray) -> BlockJacobian:
        _, jac_x = unknowns.jacobian(x[:n_arm], q)
        return jac_x if rows is None else jac_x.scaled(rows)

    # without row weights the solver's data Jacobian is this one: computed once per point
    same = rows is None and weight is None
    jac_now = jacobian(x_start)
    gauges = ident.gauge_axes(unknowns, jac_now)
    gauge = ident.gauge_rows(unknowns, gauges)

    def decide(jac_x: BlockJacobian, x: np.ndarray) -> _Decision:
        """Held directions decided at x (``jac_x``: the Jacobian there), the problem at x."""
        obs = ident.observability(unknowns, jac_x, gauge, sigma_class)
        constraints = sp.csr_matrix(sp.vstack([gauge, obs.hold_rows()]))
        return _Decision(obs, constraints, Problem(unknowns, q, measured, nuisance, constraints,
                                                   obs.scale, x_start, x, sigma_class, weight,
                                                   jac_x if same else None))

    def check(jac_x: BlockJacobian, x: np.ndarray, now: _Decision) -> _Decision | None:
        """The decision taken again at x if x holds another number of directions, else None."""
        if ident.held_count(unknowns, jac_x, gauge, sigma_class) == now.obs.hold.shape[0]:
            return None
        return decide(jac_x, x)

    now = decide(jac_now, x_start)
    z_now, f_at, nfev = _decision_point(now.problem, jac_now if same else None, on_evaluation)
    f_now: np.ndarray | None = f_at  # the residual at z_now while the problem stays the same
    x_now = now.problem.x(z_now)
    if z_now.any():  # the step lowered the cost: check the decision where it landed
        del jac_now  # one Jacobian in memory at a time
        jac_now = jacobian(x_now)
        again = check(jac_now, x_now, now)
        if again is not None:
            # the solve starts at x_now put on the new constraints (held at the start's values),
            # a held component away from it: x_now's Jacobian still serves the first step
            now, z_now, f_now = again, again.problem.z(x_now), None
    last: BlockJacobian | None = None  # the solver's last, taken at its solution: jacobian(x_now)
    at_solution: BlockJacobian | None = None  # the data Jacobian at the final x, for the covariance
    for _round in range(3):  # checked at the solution
        if _round:
            jac_now = last if last is not None else jacobian(x_now)
            last = None
            again = check(jac_now, x_now, now)
            if again is None:
                at_solution = jac_now  # the same number held: the decision stands
                break
            now, z_now, f_now = again, again.problem.z(x_now), None
        # the solve's first Jacobian is this one (handed over, not kept here: a campaign's
        # Jacobian can weigh hundreds of MB)
        handed = [jac_now] if same else []
        del jac_now
        res = now.problem.solve(z_now, settings, jac, on_evaluation=on_evaluation,
                                keep_jacobian=same, jac0=handed.pop() if handed else None,
                                f0=f_now, jac0_at=x_now)
        f_now = None
        last = now.problem.take_jacobian(res.x)
        nfev += res.nfev
        z_now = res.x
        x_now = now.problem.x(z_now)
    else:
        at_solution = last  # three rounds: the last solve's (None if it kept none)
    return _Fit(unknowns, unvisited, gauges, now.obs, now.constraints, now.problem, res, x_now,
                nfev, at_solution if same else None)


class _Decision(NamedTuple):
    """What the data determine, decided at one point, and the problem it constrains."""

    obs: ident.Observability
    constraints: sp.csr_matrix
    """Gauge rows, then the held directions' rows, over the free arm entries, (k, n_arm)."""
    problem: Problem
    """Constrained by ``constraints``, preconditioned at the point of the decision."""


def _decision_point(problem: Problem, jac0: BlockJacobian | None,
                    on_evaluation: Callable[[float], None]
                    ) -> tuple[np.ndarray, np.ndarray, int]:
    """Return where the held directions are checked before the solve, its residual, evaluations.

    One Gauss-Newton step of ``problem`` (constrained by the directions held at the start, its
    ``x_ref``, and preconditioned there) from the start: the ``dz`` minimising
    ``||f(0) + J P dz||`` (:meth:`Problem.newton_step`). The residual is nearly linear in the
    errors, so the step lands near the solution (on the benchmark's campaigns, 1,600 to 160,000
    samples, its cost is within 0.2 % of the minimum), where a direction that only the start
    makes degenerate (the nominal tool on the A7 axis hides the A7 rotations) has about the
    singular value it has at the solution. Whether the step is taken depends on no start value
    or data set: only on whether it lowered the sum of squared residuals.

    Args:
        problem: the problem decided at the start (z = 0 is its ``x_ref``, the start).
        jac0: :meth:`Problem.data_jacobian` at the start when the caller has it,
            shape (3N, n_arm), m per unit.
        on_evaluation: progress, called with the RMS of each of the two residuals (m).

    Returns:
        The reduced coordinates after the step, shape (n_z,), if the step lowered the sum of
        squared residuals, else the start's (zeros); :meth:`Problem.fun` there (the solve from
        that point does not evaluate it again); and the residual evaluations taken (2).
    """
    z0 = np.zeros(problem.p.shape[1])
    f0 = problem.fun_reported(z0, on_evaluation)
    z1 = problem.newton_step(z0, f0, jac0)
    del jac0
    f1 = problem.fun_reported(z1, on_evaluation)
    # the plain sum of squares even for a robust loss: the point only decides the held directions
    # and starts the solve, which minimises the loss from there
    return (z1, f1, 2) if f1 @ f1 < f0 @ f0 else (z0, f0, 2)


def _robust(first: _Fit, fit: Callable[[np.ndarray | None], _Fit],
            reweight: Callable[[_Fit, np.ndarray], _Fit], base_w: np.ndarray
            ) -> tuple[np.ndarray, bool, _Fit]:
    """Reject outliers from a least-squares fit (see :mod:`aacmm_pin.fit.robust`).

    Huber reweighting on the least-squares structure until the weights settle (a convex start
    that gross outliers cannot capture), then hard rejection: refit from the start values with
    the samples within ``OUTLIER_K`` robust sigmas, the structure (unvisited nodes, gauges, held
    directions) decided on them, until the rejected set no longer changes. ``fit(keep)``
    identifies from the start values with the samples of ``keep``; ``reweight(fit, w)`` solves
    the same structure again from its solution with sample weights ``w``. Returns the mask of
    samples kept, whether the set settled and the final fit (its ``nfev`` counts every solve).
    """
    now, nfev = first, first.nfev
    n = len(base_w)

    def norms_of(f: _Fit) -> np.ndarray:
        return rob.whitened_norms(f.problem.data_residuals(f.x), base_w)

    def fraction(f: _Fit, kept: int) -> float:
        n_det = int(f.problem.n_arm - f.obs.hold.shape[0] - len(f.gauges) + f.problem.n_frame)
        return float(max(3 * kept + f.problem.n_lengths - n_det, 1) / (3 * kept))

    norms = norms_of(now)
    weight = np.ones(n)
    for _ in range(rob.MAX_HUBER_ITERATIONS):
        new = rob.huber_weights(norms, rob.robust_scale(norms, fraction(now, n)))
        if np.max(np.abs(new - weight)) < rob.WEIGHT_TOL:
            break
        weight = new
        now = reweight(now, weight)
        nfev += now.nfev
        norms = norms_of(now)
    mask, refitted = np.zeros(n, bool), False  # refitted: ``now`` is the fit without ``mask``
    _, first_jac = first.unknowns.jacobian(first.x[:first.problem.n_arm], first.problem.q)
    node_size = float(first.unknowns.arm.sizes.map_node)
    for _ in range(rob.MAX_REJECT_ITERATIONS):
        scale = rob.robust_scale(norms, fraction(now, n - int(mask.sum())))
        unseen = rob.unseen_variance(first_jac.nodes, ~mask, node_size) * base_w ** 2
        out = rob.flag_unseen(norms, scale, unseen)
        if refitted and np.array_equal(out, mask):
            return ~mask, True, now._replace(nfev=nfev)
        if not out.any():  # nothing to reject: the least-squares fit stands, if it agrees
            norms = norms_of(first)
            if not rob.flag(norms, rob.robust_scale(norms, fraction(first, n))).any():
                return ~out, True, first._replace(nfev=nfev)
        mask, refitted = out, True
        now = fit(~mask)
        nfev += now.nfev
        norms = norms_of(now)
    return ~mask, False, now._replace(nfev=nfev)


def _sigma(data_residuals: np.ndarray, n_params: int, given: float | None) -> float:
    """Return the given noise, or the residual-based estimate sqrt(SSR / (m - p))."""
    if given is not None:
        return float(given)
    dof = max(data_residuals.size - n_params, 1)
    return float(np.sqrt(np.sum(data_residuals ** 2) / dof))


def refit(cal: Calibration, measured: np.ndarray, iterations: int = 10,
          factor: Factor | None = None) -> tuple[np.ndarray, bool]:
    """Re-identify with other measured sphere centres, keeping the calibration's structure.

    The unknowns, gauges, held directions and preconditioner of ``cal`` are kept and the solve
    starts from its solution: what a Monte Carlo trial needs. Gauss-Newton steps on the nonlinear
    residual with the Jacobian at the calibration's solution (factored once: pass ``factor`` from
    ``cal.problem.factor(cal.problem.z(cal.x))`` to share it between trials) until the step is
    below 1e-12 of the reduced scale; ``least_squares`` takes over where that does not converge
    (or for a robust loss).

    Args:
        cal: a calibration from :func:`identify`.
        measured: measured sphere centres in the MT-CS, shape (N, 3), m (e.g. perturbed).
        iterations: most Gauss-Newton steps.
        factor: the factored Jacobian at the calibration's solution (computed when None).

    Returns:
        The full solution vector (arm entries then nest offsets, as ``cal.x``) and whether it
        converged.
    """
    problem = cal.problem.with_measured(measured)
    z = problem.z(cal.x)
    if cal.settings.loss == "linear" and problem.dense(z.size):
        z_gn, ok = problem.gauss_newton(z, cal.problem.factor(z) if factor is None else factor, iterations)
        if ok:
            return problem.x(z_gn), True
        z = z_gn
    res = problem.solve(z, cal.settings)
    return problem.x(res.x), bool(res.success)
