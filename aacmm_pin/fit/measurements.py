r"""What an identification fits, checked, and the noise each sample is stated to have.

:func:`measurements` turns a campaign into one row per sample (:class:`Measurements`): SPAT
samples with their measured sphere centres (paper Eq. 3, :func:`measured_positions`) and R-Test
nests, absolute tool points with their instrument groups, length-bar readouts with their sockets as
nests and the calibrated distances as length rows. :func:`check_campaign` and :func:`check_points`
raise :class:`IdentificationError` for data that cannot be identified. :func:`stated_noise` is the
one policy for the stated noise of every sample (what :func:`aacmm_pin.fit.identification.identify`
weighs the rows by and :func:`aacmm_pin.analyses.discovery.discover` judges the residual against).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from aacmm_pin.data.campaign import Campaign, PointLog, SpatLog, StatedNoise
from aacmm_pin.distributions import chi2_isf
from aacmm_pin.errors import AacmmError
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.samples import Samples
from aacmm_pin.units import SIGMA_POINT, SOCKET_PRIOR

BAR_ID = 100_000
"""A length-bar socket used as a nest has id ``BAR_ID * placement + socket index`` (sorted names)."""


class IdentificationError(AacmmError):
    """The campaign cannot be identified (too few locations, no motion, non-finite values)."""


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


def check_points(campaign: Campaign, arm: Arm, noise: float | None = None) -> PointLog:
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
    if noise is None:  # the stated noise of points without a sigma_um column, m
        noise = campaign.noise.point if campaign.noise is not None else SIGMA_POINT
    for g in np.unique(points.group):
        rows = points.group == g
        pts = points.point[rows]
        sigma = noise if points.sigma is None else float(np.median(points.sigma[rows]))
        spread = _least_spread(pts, sigma) if len(pts) >= 4 else None
        if len(pts) < 4 or spread is not None:
            beyond = "" if spread is None else (
                f" (their least spread direction {spread * 1e6:.3g} um RMS is no more than "
                f"the stated noise {sigma * 1e6:.3g} um explains, p >= {SPREAD_P:g})")
            raise IdentificationError(
                f"the measured points of group {g} ({len(pts)} points) lie on a line or a plane"
                f"{beyond}: they cannot fix that instrument's frame (measure 4 or more poses "
                "spread in 3-D)")
    return points


SPREAD_P = 1e-3
"""Level of the test that an instrument group's points spread in every direction beyond their
stated noise (:func:`check_points`): above it, what spread they have may be noise alone."""


def _least_spread(pts: np.ndarray, sigma: float) -> float | None:
    """Return the RMS spread of points (n, 3) along their least spread direction, m, if noise explains it.

    Noise of standard deviation ``sigma`` per coordinate gives a sum of squares along any fixed
    direction of sigma^2 chi-square(n - 1); the smallest one over the directions is at most that.
    Returns None when it is beyond the (1 - :data:`SPREAD_P`) quantile: the points span 3-D.
    """
    centred = pts - pts.mean(axis=0)
    ss = float(np.linalg.svd(centred, compute_uv=False)[-1] ** 2)
    if ss / sigma ** 2 > chi2_isf(SPREAD_P, len(pts) - 1) and \
            np.linalg.matrix_rank(centred, tol=1e-4) == 3:
        return None
    return float(np.sqrt(ss / len(pts)))


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
    :meth:`aacmm_pin.fit.identification_result.Calibration.group_label`)."""
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


def _bar_part(campaign: Campaign, arm: Arm, sigma: float) -> Measurements:
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
    return Measurements(log.q, np.full((len(nest), 3), np.nan), ids[nest],
                        Samples.of_log(arm, log), np.full(len(nest), sigma), nest,
                        np.full(len(keys), SOCKET_PRIOR),
                        tuple((int(i), f"bar{p}{s}") for i, (p, s) in zip(ids, keys)),
                        lengths=np.array(lengths, dtype=float).reshape(-1, 3))


def _join(parts: list[Measurements], arm: Arm, point_noise: float) -> Measurements:
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
                            np.full(k, np.nan if p.nest is not None else point_noise)
                            for k, p in zip(n, parts)])
    q = np.concatenate([p.q for p in parts])
    return Measurements(q, np.concatenate([p.measured for p in parts]),
                        np.concatenate([p.group for p in parts]),
                        Samples.concatenate([p.samples for p in parts]), sigma, np.concatenate(nest),
                        np.concatenate([p.nest_sigma for p in parts]),
                        tuple(k for p in parts for k in p.nest_keys), np.concatenate(frame),
                        tuple(frames), np.concatenate(lengths))


def measurements(campaign: Campaign, arm: Arm, use_rtest: bool, use_bar: bool = False,
                 noise: StatedNoise | None = None) -> Measurements:
    """Return what an identification of ``campaign`` fits (checked; see :class:`Measurements`).

    SPAT: the measured sphere centres (Eq. 3), the R-Test locations, whose nest offsets are
    estimated. Points: the measured tool points and their instrument group; without SPAT the
    first group's frame is the main one (X0 and translation), every other group has a frame of
    its own. ``use_bar``: the length-bar readouts too, each socket a nest whose position is
    estimated, the calibrated distances between a placement's sockets as length rows.
    ``noise``: the stated noise per kind (default: the campaign's, else the defaults): points
    without a ``sigma_um`` column and the bar's sockets get theirs.
    """
    noise = noise or campaign.noise or StatedNoise()
    parts = []
    if campaign.spat is not None or campaign.points is None:
        parts.append(_spat_part(campaign, arm, use_rtest))
    if campaign.points is not None:
        points = check_points(campaign, arm, noise.point)
        ids = np.unique(points.group)
        own = ids if parts else ids[1:]  # groups with a frame of their own
        frame = np.where(np.isin(points.group, own), np.searchsorted(own, points.group), -1)
        parts.append(Measurements(points.q, points.point, points.group if not parts
                                  else -points.group, Samples.of_log(arm, points),
                                  points.sigma, frame=frame if own.size else None,
                                  frame_groups=tuple(int(g) for g in own)))
    if use_bar:
        parts.append(_bar_part(campaign, arm, noise.socket))
    if len(parts) == 1 and not use_bar:
        part = parts[0]
        if part.frame is None and part.nest is not None:  # SPAT alone: as before
            return part._replace(sigma=None)
        return part
    return _join(parts, arm, noise.point)



def stated_noise(campaign: Campaign, meas: Measurements, noise: StatedNoise) -> np.ndarray:
    """Return the stated noise of every sample per coordinate, shape (N,), m.

    SPAT samples: ``noise.rtest``; tool points: their ``sigma_um`` column, else
    ``noise.point``; length-bar readouts: the campaign's stated socket noise
    (``campaign.json`` ``socket``, else :data:`aacmm_pin.units.SIGMA_SOCKET`, set by
    :func:`measurements`).

    Args:
        campaign: the campaign ``meas`` was made from.
        meas: its measurements (:func:`measurements`).
        noise: the stated noise per kind (discovery: the campaign's or the user's; an
            identification: the R-Test noise its solve assumes and the default point noise).
    """
    if meas.sigma is None:
        return np.full(len(meas.q), noise.rtest if campaign.spat is not None else noise.point)
    points = campaign.points
    stated = np.where(np.isnan(meas.sigma), noise.rtest, meas.sigma)
    if points is not None and points.sigma is None:  # points without sigma_um: the instrument's
        if campaign.spat is not None:  # the points' groups are negative beside SPAT
            rows = meas.group < 0
        else:  # every sample but the length bar's (its sockets are nests)
            rows = np.ones(len(stated), dtype=bool) if meas.nest is None else meas.nest < 0
        stated = np.where(rows, noise.point, stated)
    out: np.ndarray = stated
    return out
