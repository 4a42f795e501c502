"""What every fit of one identification shares: measurements, start, unknowns, noise, nuisance.

:func:`fit_setup` makes it (:class:`FitSetup`) from a campaign and the options: the stated noise
per kind (:func:`solve_noise`), the start's frame (a Kabsch fit of the group centres), the R-Test
nests held or estimated, the instrument frames' starts and the bar sockets' start positions.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from aacmm_pin.data.campaign import Campaign, StatedNoise
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.fit import plausibility
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit.data_rows import Nuisance
from aacmm_pin.fit.fit_options import FitOptions
from aacmm_pin.fit.measurements import Measurements, measurements, stated_noise
from aacmm_pin.fit.solver_values import Budget, SolverSettings
from aacmm_pin.fit.unknowns import FrameKey, NestKey, UnknownKey, Unknowns
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.units import SIGMA_BAR


class FitSetup(NamedTuple):
    """What every fit of one identification shares."""

    meas: Measurements
    """The measurements (R-Test nests dropped when they are held fixed)."""
    full_u: Unknowns
    """Every unknown of the model, before the unvisited nodes are fixed."""
    start: Parameters
    """Start values."""
    has_spat: bool
    """Whether SPATs are fitted."""
    sigma_class: float
    """The noise per coordinate the solves assume, m (a row of weight 1 has it)."""
    stated: np.ndarray | None
    """Stated noise of every sample, shape (N,), m (:func:`~aacmm_pin.fit.measurements.stated_noise`);
    None: every sample has ``sigma_class`` and the rows are not weighted."""
    base_w: np.ndarray
    """Weight of every sample, ``sigma_class / stated``, shape (N,)."""
    nuisance: Nuisance
    """Nests, instrument frames and length rows."""
    measured: np.ndarray
    """Measured points, bar sockets at their start positions, shape (N, 3), m."""
    nuisance_keys: list[UnknownKey]
    """What each entry after the arm's is."""
    settings: SolverSettings
    """How every solve minimises."""
    sources: tuple[list[str], np.ndarray, np.ndarray]
    """The campaign file (the kind), line and log row of every sample (:func:`rob.sample_sources`)."""
    noise: StatedNoise
    """The stated noise per kind the solves use (:func:`solve_noise`)."""


def solve_noise(campaign: Campaign, options: FitOptions) -> StatedNoise:
    """Return the stated noise per kind that every solve of an identification uses.

    The one policy, from the sources :func:`aacmm_pin.data.logs.noise_summary` prints: the
    options' ``sigma`` (the campaign's main kind: R-Test readings, else points) and
    ``sigma_location``, over ``options.noise`` (a caller's, e.g. discover's ``--sigma-*-um``),
    over the campaign's ``campaign.json`` (``noise_um``, else its instrument's), over the defaults.
    Points with a ``sigma_um`` column keep it (:func:`~aacmm_pin.fit.measurements.stated_noise`).
    """
    noise = options.noise or campaign.noise or StatedNoise()
    if options.sigma is not None:
        spat = campaign.spat is not None or campaign.points is None
        noise = replace(noise, rtest=options.sigma) if spat else replace(noise, point=options.sigma)
    if options.sigma_location is not None:
        noise = replace(noise, location=options.sigma_location)
    return noise


def fit_setup(campaign: Campaign, arm: Arm, options: FitOptions, budget: Budget | None,
           fixed_nests: bool) -> FitSetup:
    """Return the measurements, unknowns, noise and nuisance shared by the fits."""
    noise = solve_noise(campaign, options)
    meas = measurements(campaign, arm, options.use_rtest, options.use_bar, noise)
    if fixed_nests:
        meas = _without_rtest_nests(meas)
    q, group, samples, stated = meas.q, meas.group, meas.samples, meas.sigma
    main = ~np.isnan(meas.measured[:, 0]) & (True if meas.frame is None else meas.frame < 0)
    if campaign.points is not None:  # points in other units, or not this arm's: before the fit
        pts = point_rows(campaign, meas) & ~np.isnan(meas.measured[:, 0])
        nominal = stylus_positions(arm, Parameters.nominal(arm, options.step_deg), q[pts], "r",
                                   tool=None if samples.tool is None else samples.tool[pts])
        plausibility.check_point_spread(meas.measured[pts], nominal, group[pts],
                                        arm.sizes_label)
    # every sample: the columns as they are (a copy only to make them C-ordered, as selecting
    # rows makes them: the sums of the frame's fit in the same order), not N x n_axes copied
    rows = _all_rows if main.all() else (lambda a: a[main])
    start = options.start or _initial_frame(
        arm, Parameters.nominal(arm, options.step_deg), rows(q), rows(meas.measured), rows(group),
        None if samples.tool is None else rows(samples.tool))
    axes = tuple(arm.measured_axes) if options.map_axes is None else tuple(options.map_axes)
    if coupled := [a for a in axes if 1 <= a <= arm.n_axes and arm.coupled[a - 1]]:
        raise ValueError(f"map_axes: A{coupled[0]} ({arm.axis_names[coupled[0] - 1]}) is a coupled "
                         "joint: it has no encoder, so no map")
    full_u = Unknowns.full(arm, start, axes if options.model == "proposed" else (),
                           tuple(t for t in options.extensions if t.is_extension), samples)
    has_spat = campaign.spat is not None or campaign.points is None
    sigma_class = (noise.rtest if has_spat else noise.point if stated is None
                   else float(np.median(stated)))
    if stated is not None:  # per-sample noise stated
        stated = stated_noise(campaign, meas, noise)
    nuisance, measured, nuisance_keys = _nuisance(arm, start, meas, sigma_class, noise.location)
    base_w = np.ones(len(q)) if stated is None else sigma_class / stated
    settings = SolverSettings(loss=options.loss, f_scale=options.f_scale or 3 * sigma_class,
                              max_nfev=options.solve_nfev, budget=budget)
    return FitSetup(meas, full_u, start, has_spat, sigma_class, stated, base_w, nuisance, measured,
                  nuisance_keys, settings, rob.sample_sources(campaign, options.use_bar), noise)


def _all_rows(a: np.ndarray) -> np.ndarray:
    """Return ``a`` C-ordered: itself if it is (as ``a[mask]`` would be, without the copy)."""
    return np.ascontiguousarray(a)


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
    socket = np.isnan(meas.measured[:, 0])
    # completed (sockets): a copy; else the measured points themselves, C-ordered as a copy is
    measured = meas.measured.copy() if socket.any() else np.ascontiguousarray(meas.measured)
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


def point_rows(campaign: Campaign, meas: Measurements) -> np.ndarray:
    """Return which samples are absolute points, shape (N,) (as :func:`stated_noise` tells them)."""
    if campaign.points is None:
        return np.zeros(len(meas.q), dtype=bool)
    if campaign.spat is not None:  # the points' groups are negative beside SPAT
        out: np.ndarray = meas.group < 0
        return out
    return np.ones(len(meas.q), dtype=bool) if meas.nest is None else meas.nest < 0
