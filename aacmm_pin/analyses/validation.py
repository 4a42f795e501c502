"""Length-bar validation (paper Fig. 9): error of the mean socket distances per bar placement."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from aacmm_pin.analyses.bar_scatter import SocketScatter, socket_scatter
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.data.problem_log import MAX_LIKE
from aacmm_pin.effects.calibrated import predict, stylus_positions
from aacmm_pin.errors import AacmmError, CampaignFormatError, Problem
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples
from aacmm_pin.units import SIGMA_SOCKET


@dataclass(frozen=True)
class ValidationResult:
    """Length errors of a calibrated arm on the length bar."""

    placements: list[int]
    """Bar placements, in file order of first appearance."""
    pairs: list[tuple[str, str]]
    """Calibrated socket pairs (from, to), as in bar.csv."""
    errors: np.ndarray
    """Measured minus calibrated distance, shape (n_placements, n_pairs), in m; NaN where a
    placement did not measure both sockets of a pair."""
    warnings: tuple[str, ...] = ()
    """What makes these errors doubtful, each naming the file and line: a readout whose stylus
    centre is far from the other readouts of its socket (a wrong readout, socket or placement, or
    a posture the calibration's SPATs did not cover), a length error too large for a calibrated
    arm (a wrong bar.csv length, e.g. its units), or readouts that scatter about their sockets far
    more than the calibration's accuracy allows (:mod:`aacmm_pin.analyses.bar_scatter`: a readout column in
    other units, another or a changed arm)."""
    scatter: SocketScatter | None = None
    """The readouts' scatter about their sockets against the calibration's accuracy (None: not
    computed)."""

    @property
    def rms(self) -> float:
        """RMS of all length errors, m (pairs not measured in a placement are left out)."""
        return float(np.sqrt(np.nanmean(self.errors ** 2)))

    @property
    def max_abs(self) -> float:
        """Largest absolute length error, m (pairs not measured in a placement are left out)."""
        return float(np.nanmax(np.abs(self.errors)))

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form: ``{"placements": [{"placement": 1, "AB_um": ..}], "rms_um", ..}``."""
        rows = [{"placement": int(k), **{f"{a}{b}_um": None if np.isnan(e) else float(e * 1e6)
                                         for (a, b), e in zip(self.pairs, errs)}}
                for k, errs in zip(self.placements, self.errors)]
        return {"placements": rows, "rms_um": self.rms * 1e6, "max_abs_um": self.max_abs * 1e6,
                "socket_scatter": None if self.scatter is None else self.scatter.to_dict(),
                "warnings": list(self.warnings)}

    def table(self) -> str:
        """Return a plain-text table of the errors in um."""
        head = "placement " + " ".join(f"{a + '-' + b + ' (um)':>12}" for a, b in self.pairs)
        lines = [head] + [f"{k:>9} " + " ".join(f"{e * 1e6:>12.2f}" for e in errs)
                          for k, errs in zip(self.placements, self.errors)]
        lines.append(f"RMS {self.rms * 1e6:.2f} um, max |error| {self.max_abs * 1e6:.2f} um")
        if self.scatter is not None:
            lines.append(self.scatter.summary())
        lines += [f"WARNING: {w}" for w in self.warnings]
        return "\n".join(lines)


@dataclass(frozen=True)
class BarPairs:
    """Which readouts form each length error: the (placement, pair) entries measured in full."""

    index: list[tuple[int, int]]
    """Per error: its row (placement) and column (pair) in :attr:`ValidationResult.errors`."""
    rows: list[tuple[np.ndarray, np.ndarray]]
    """Per error: indices of the readouts in the first and in the second socket."""
    length: np.ndarray
    """Calibrated length of each error's pair, shape (n,), m."""
    placements: list[int]
    """Bar placements, in file order of first appearance."""
    pairs: list[tuple[str, str]]
    """Calibrated socket pairs (from, to), as in bar.csv."""


def bar_pairs(campaign: Campaign, mask: np.ndarray | None = None) -> BarPairs:
    """Return the length errors a campaign's bar log measures (readouts in ``mask``, shape (M,)).

    Raises:
        AacmmError: if the campaign has no length-bar data.
    """
    log = campaign.lengthbar
    if log is None or not campaign.bar:
        where = "the campaign" if campaign.source is None else str(campaign.source)
        raise AacmmError(f"{where} has no length-bar data (lengthbar.csv and bar.csv): measure the "
                         "calibrated bar (or absolute points, for validate) to compare against")
    keep = np.ones(len(log.q), dtype=bool) if mask is None else mask
    placements = list(dict.fromkeys(int(k) for k in log.placement))
    pairs = list(campaign.bar)
    index, rows, length = [], [], []
    for i, k in enumerate(placements):
        here = (log.placement == k) & keep
        for j, (a, b) in enumerate(pairs):
            ra, rb = (np.flatnonzero(here & (log.socket == s)) for s in (a, b))
            if ra.size and rb.size:
                index.append((i, j))
                rows.append((ra, rb))
                length.append(campaign.bar[(a, b)])
    return BarPairs(index, rows, np.array(length), placements, pairs)


def pair_errors(points: np.ndarray, pairs: BarPairs) -> tuple[np.ndarray, np.ndarray]:
    """Return each length error (n,), m, and the unit vector between its sockets (n, 3).

    An error is the distance of the mean socket points less the calibrated length.

    Args:
        points: modelled stylus centres of the bar readouts, shape (M, 3), m (any one frame).
        pairs: from :func:`bar_pairs`.
    """
    if not pairs.rows:
        return np.zeros(0), np.zeros((0, 3))
    d = np.array([points[rb].mean(axis=0) - points[ra].mean(axis=0) for ra, rb in pairs.rows])
    dist = np.linalg.norm(d, axis=1)
    return dist - pairs.length, d / dist[:, None]


def pair_weights(pairs: BarPairs, unit: np.ndarray, n_readouts: int) -> np.ndarray:
    """Return W, shape (n, 3M), with W @ d(points) = d(errors) (points flattened sample-major)."""
    w = np.zeros((len(pairs.rows), 3 * n_readouts))
    for i, ((ra, rb), u) in enumerate(zip(pairs.rows, unit)):
        for sign, r in ((-1.0, ra), (1.0, rb)):
            w[i, (3 * r[:, None] + np.arange(3)).ravel()] = sign * np.tile(u, r.size) / r.size
    return w


def as_table(pairs: BarPairs, values: np.ndarray) -> np.ndarray:
    """Return per-error values (n, ...) laid out as (n_placements, n_pairs, ...), NaN elsewhere."""
    out = np.full((len(pairs.placements), len(pairs.pairs), *values.shape[1:]), np.nan)
    for (i, j), v in zip(pairs.index, values):
        out[i, j] = v
    return out


@dataclass(frozen=True)
class PointValidation:
    """Errors of a calibrated arm at absolutely measured tool points (laser tracker, mocap)."""

    errors: np.ndarray
    """Predicted minus measured point in the instrument frame, shape (N, 3), m."""
    lines: np.ndarray | None
    """1-based line of each point in points.csv, shape (N,), or None."""
    fitted_groups: tuple[int, ...] = ()
    """Instrument groups whose frame is not the calibration's and was fitted to the predicted
    points (6 unknowns each; :func:`points_in_main_frame`)."""

    @property
    def distances(self) -> np.ndarray:
        """Length of every error, shape (N,), m."""
        out: np.ndarray = np.linalg.norm(self.errors, axis=1)
        return out

    @property
    def mean(self) -> float:
        """Mean error length, m."""
        return float(np.mean(self.distances))

    @property
    def rms(self) -> float:
        """RMS error length, m."""
        return float(np.sqrt(np.mean(self.distances ** 2)))

    @property
    def max(self) -> float:
        """Largest error length, m."""
        return float(np.max(self.distances))

    def table(self) -> str:
        """Return a one-line summary in mm."""
        worst = int(np.argmax(self.distances))
        where = f" (line {int(self.lines[worst])})" if self.lines is not None else ""
        note = "" if not self.fitted_groups else (
            f"; the frame of group{'s' if len(self.fitted_groups) > 1 else ''} "
            f"{', '.join(map(str, self.fitted_groups))} is not the calibration's: fitted to "
            "these points (6 unknowns each) before comparing")
        return (f"{len(self.errors)} points: mean error {self.mean * 1e3:.4f} mm, RMS "
                f"{self.rms * 1e3:.4f} mm, max {self.max * 1e3:.4f} mm{where}{note}")

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (mm)."""
        return {"n_points": int(len(self.errors)), "mean_mm": self.mean * 1e3,
                "rms_mm": self.rms * 1e3, "max_mm": self.max * 1e3,
                "fitted_frame_groups": list(self.fitted_groups),
                "errors_mm": (self.errors * 1e3).tolist()}


def points_in_main_frame(arm: Arm, params: Parameters, campaign: Campaign
                         ) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Return the predicted and measured tool points in the calibration's frame, and the groups fitted.

    As :func:`aacmm_pin.fit.measurements.measurements` assigns frames: without SPAT the lowest
    instrument group is measured in the calibration's frame (X0 and translation); every other group
    (all of them beside SPAT) has a frame of its own, which the calibration does not store: its
    points are mapped by the rigid transform that best fits them to the predicted points (what an
    identification estimates as that frame's six unknowns).

    Returns:
        ``(predicted, measured, fitted)``: shapes (N, 3), (N, 3) in m (the calibration's MT-CS),
        and the groups whose frame was fitted.
    """
    from scipy.spatial.transform import Rotation

    points = campaign.points
    if points is None:
        raise AacmmError("the campaign has no absolute points (points.csv)")
    pred = stylus_positions(arm, params, points.q, frame="mt", samples=Samples.of_log(arm, points))
    measured = points.point.copy()
    ids = np.unique(points.group)
    own = ids if campaign.spat is not None else ids[1:]
    for g in own:
        sel = points.group == g
        cp, cm = pred[sel].mean(axis=0), measured[sel].mean(axis=0)
        if sel.sum() > 1:
            rot = Rotation.align_vectors(pred[sel] - cp, measured[sel] - cm)[0].as_matrix()
        else:
            rot = np.eye(3)
        measured[sel] = (measured[sel] - cm) @ rot.T + cp
    return pred, measured, tuple(int(g) for g in own)


def validate_points(arm: Arm, params: Parameters, campaign: Campaign) -> PointValidation:
    """Compare the calibrated arm's tool points with a campaign's absolutely measured points.

    The points are predicted in the instrument frame of the calibration (its ``base_to_mt``
    transform): a test campaign must be measured with the same instrument set-up. Points of a
    group with a frame of its own (every group beside SPAT, every group but the lowest without)
    are compared after fitting that frame (:func:`points_in_main_frame`; the result names them).

    Raises:
        AacmmError: if the campaign has no points.
    """
    pred, measured, fitted = points_in_main_frame(arm, params, campaign)
    assert campaign.points is not None
    return PointValidation(pred - measured, campaign.points.lines, fitted)


def validate(arm: Arm, params: Parameters, campaign: Campaign,
             accuracy: float | None = None) -> ValidationResult:
    """Compare the calibrated arm's mean socket distances with the calibrated bar.

    For every placement, the mean stylus centre of the postures in each socket is taken (r-CS), and
    the distance between the sockets of every pair of bar.csv is compared with its calibrated length.

    Args:
        arm: the arm the parameters belong to.
        params: the calibration.
        campaign: a campaign with length-bar data.
        accuracy: the accuracy per coordinate the calibration claims, m
            (:attr:`Calibration.accuracy <aacmm_pin.fit.identification.Calibration.accuracy>`, or
            :func:`aacmm_pin.analyses.bar_scatter.read_accuracy` of its folder): the readouts' scatter about
            their sockets is compared with it (a warning beyond the limit of
            :mod:`aacmm_pin.analyses.bar_scatter`); None: the scatter is reported, not compared.

    Raises:
        AacmmError: if the campaign has no length-bar data.
    """
    pairs = bar_pairs(campaign)
    log = campaign.lengthbar
    assert log is not None
    points = predict(arm, params, log.q, Samples.of_log(arm, log))
    errors = pair_errors(points, pairs)[0]
    scatter = socket_scatter(points, log.placement, log.socket, accuracy,
                             campaign.noise.socket if campaign.noise else SIGMA_SOCKET)
    warning = scatter.warning()
    return ValidationResult(pairs.placements, pairs.pairs, as_table(pairs, errors),
                            tuple(_socket_warnings(campaign, points)
                                  + _length_warnings(campaign, pairs, errors)
                                  + ([warning] if warning else [])), scatter)


SOCKET_SCATTER_K = 40.0
"""A bar readout is flagged beyond this many robust scatters of all readouts about their socket's
median point (the scatter of a calibrated arm is posture-dependent, its tail long: on simulated
campaigns the farthest readout lies up to 30 such scatters out)."""
SOCKET_SCATTER_MIN = 20e-6
SOCKET_SCATTER_MAX = 0.5e-3
"""The flag limit is kept within these, m: a readout 0.5 mm from its socket's median point is
flagged whatever the scatter (no arm, calibrated or not, should scatter that much)."""
LENGTH_ERROR_MAX = 0.01
"""Largest length error, as a fraction of the calibrated length, taken for an arm's error
(a larger one is a wrong length in bar.csv, e.g. in other units, or a wrong calibration)."""


def _socket_warnings(campaign: Campaign, points: np.ndarray) -> list[str]:
    """Flag readouts far from the median point of their (placement, socket), file lines named.

    The limit is :data:`SOCKET_SCATTER_K` times the robust scatter of all readouts about their
    socket's median, within :data:`SOCKET_SCATTER_MIN` .. :data:`SOCKET_SCATTER_MAX`.
    """
    log = campaign.lengthbar
    assert log is not None
    dist = np.zeros(len(points))
    for key in set(zip(log.placement.tolist(), log.socket.tolist())):
        rows = np.flatnonzero((log.placement == key[0]) & (log.socket == key[1]))
        dist[rows] = np.linalg.norm(points[rows] - np.median(points[rows], axis=0), axis=1)
    if not dist.size:
        return []
    limit = min(SOCKET_SCATTER_MAX,
                max(SOCKET_SCATTER_K * 1.4826 * float(np.median(dist)), SOCKET_SCATTER_MIN))
    where = log.lines if log.lines is not None else np.arange(len(points)) + 2
    far = np.flatnonzero(dist > limit)
    shown = [f"lengthbar.csv line {int(where[i])}: stylus centre {dist[i] * 1e6:.4g} um from its "
             f"socket's ({log.placement[i]}, {log.socket[i]}) median (limit {limit * 1e6:.3g} um): "
             "a wrong readout, socket or placement, or a posture in an angular range the "
             "calibration's SPATs did not cover (aacmm-pin plan names those ranges)"
             for i in far[:MAX_LIKE]]
    if far.size > MAX_LIKE:  # one kind of problem: a few shown, the others counted
        shown.append(f"lengthbar.csv line {int(where[far[MAX_LIKE]])}: ... and {far.size - MAX_LIKE:,}"
                     f" more readouts like it (to line {int(where[far[-1]])})")
    return shown


LENGTH_UNITS = {"inches": 25.4, "cm": 10.0, "m": 1000.0, "um": 1e-3}
"""Unit of bar.csv lengths a user may have written by mistake -> measured / stated length it gives
(the file's ``length_mm`` column wants mm)."""


SAME_FACTOR = 0.1
"""Lengths share one factor when each one's measured / stated departs from their median by at most
this share of the median's departure from 1 (lengths in inches: 25.4 each, to the arm's 1e-4; a
socket's readouts off: every pair through it changes by its own factor)."""


def _length_warnings(campaign: Campaign, pairs: BarPairs, errors: np.ndarray) -> list[str]:
    """Flag length errors beyond :data:`LENGTH_ERROR_MAX` of their calibrated length: one line.

    Returns:
        one warning naming the first such error and how many more there are, or none.

    Raises:
        CampaignFormatError: if one factor, off 1 by more than :data:`LENGTH_ERROR_MAX`, explains
            every length of bar.csv (measured / stated, averaged over the placements; within
            :data:`SAME_FACTOR` of its departure from 1): no arm errs so much and so alike, the
            lengths are in other units (named if one of :data:`LENGTH_UNITS`) or of another bar.
            With a single pair, only for a unit of :data:`LENGTH_UNITS` (a readout column in
            radians, say, changes one length by a factor too; the socket scatter flags it).
    """
    bad = [k for k, e in enumerate(errors) if abs(e) > LENGTH_ERROR_MAX * pairs.length[k]]
    if not bad:
        return []
    columns = np.array([j for _, j in pairs.index])
    ratio = np.array([1.0 + float(np.mean(errors[columns == j] / pairs.length[columns == j]))
                      for j in range(len(pairs.pairs))])
    common = float(np.median(ratio))
    same = bool(np.all(np.abs(ratio - common) <= SAME_FACTOR * abs(common - 1.0)))
    unit = next((u for u, f in LENGTH_UNITS.items() if abs(common / f - 1.0) <= LENGTH_ERROR_MAX),
                None)
    if abs(common - 1.0) > LENGTH_ERROR_MAX and same and (unit or len(ratio) > 1):
        path = "bar.csv" if campaign.source is None else campaign.source / "bar.csv"
        (a, b), stated = pairs.pairs[0], campaign.bar[pairs.pairs[0]]
        hint = (f"the lengths look like {unit} (measured / stated = {common:.4g}); length_mm "
                "wants mm" if unit else f"every length is off by the same factor {common:.4g}: "
                "other units, or another bar's lengths")
        raise CampaignFormatError([Problem(
            path, None, "length_mm", f"every length is off by more than {LENGTH_ERROR_MAX:.0%} "
            f"({a}-{b}: {stated * 1e3:.6g} mm in the file, {ratio[0] * stated * 1e3:.6g} mm "
            f"measured): {hint}")])
    i, j = pairs.index[bad[0]]
    (a, b), e, length = pairs.pairs[j], errors[bad[0]], pairs.length[bad[0]]
    more = f" (and {len(bad) - 1} more like it)" if len(bad) > 1 else ""
    return [f"bar.csv {a}-{b} at placement {pairs.placements[i]}: length error {e * 1e3:.4g} mm "
            f"is over {LENGTH_ERROR_MAX:.0%} of the calibrated {length * 1e3:.6g} mm{more}: a "
            "wrong length (units?) or calibration"]
