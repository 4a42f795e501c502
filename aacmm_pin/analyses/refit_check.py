r"""Held-out error by refits: each fold's poses predicted by the model fitted without them.

Discovery scores a candidate on the fit of all samples, linearised there, with the arm's sizes as
priors (:mod:`aacmm_pin.analyses.linear_scorer`). Where the model's residual is far beyond the
stated noise (the Barrett WAM's laser-tracker grid: 1.30 mm per coordinate against the tracker's
20 um, priors widened 12x) that score is an approximation the data cannot vouch for;
:func:`refit_error` is the test that needs none (on the WAM it confirms each of the six steps,
2.12 -> 1.52 mm, docs/real-robots.md) and :func:`refit_rule` says where discovery applies it
(:data:`REFIT_RATIO`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from aacmm_pin.analyses.validation import validate_points
from aacmm_pin.data.campaign import Campaign, StatedNoise
from aacmm_pin.data.poses import POSE_COLUMN, pose_folds, pose_ids
from aacmm_pin.effects.base import ModelSpec
from aacmm_pin.errors import AacmmError
from aacmm_pin.fit.identification import identify
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.model.arm import Arm

REFIT_FOLDS = 5
"""Folds of :func:`refit_error` (the poses shuffled with seed 0, :func:`pose_folds`), as the
README's k-fold rows."""

REFIT_RATIO = 10.0
r"""Discovery refits where the fit's residual RMS per coordinate exceeds the stated point noise by
more than this: the residual is then model error by 99 % of its variance (:math:`1 - 1/10^2`), not
the noise the linearised scores' tests and priors are stated in. Measured at the start (DH) fit:
the UR5's laser-tracker grid 3.2x (64.8 um against 20 um; its steps hold on its separate test
poses), the WAM's 65x; the suite's simulated points campaigns 0.3-7.7x (the humanoid traps
7.2-7.7x), but the torso with lateral compliance hidden on T1, L2, R2 18x: refit-checked there,
discovery names the same terms on all five seeds (``tests/test_lateral_compliance.py``, slow) in
1.5x the time. Campaigns with SPATs (every AACMM campaign) are never refitted: their held-out score
leaves whole R-Test locations out."""


OUT_FACTOR = 1e6
"""A held-out point's stated noise in a fold's fit, times its own (:func:`refit_error`)."""


def weighted_out(campaign: Campaign, rows: np.ndarray, noise: StatedNoise | None = None
                 ) -> Campaign:
    """Return the campaign with the points ``rows`` held out of a fit, kept in sequence.

    Their stated noise is :data:`OUT_FACTOR` times their own (a ``sigma_um`` column, else
    ``noise``'s or the campaign's point noise): weight 1e-12, nothing of them is fitted, and every
    pose keeps the direction each axis moved in to reach it.

    Raises:
        AacmmError: if the campaign has no points.
    """
    points = campaign.points
    if points is None:
        raise AacmmError("refit_error: the campaign has no points (points.csv)")
    sigma = points.sigma.copy() if points.sigma is not None else np.full(
        len(points.q), (noise or campaign.noise or StatedNoise()).point)
    sigma[rows] *= OUT_FACTOR
    return dataclasses.replace(campaign, points=dataclasses.replace(
        points, columns={**points.columns, "sigma_um": sigma}))


def refit_error(campaign: Campaign, arm: Arm, model: ModelSpec = ModelSpec(), *,
                folds: int = REFIT_FOLDS, noise: StatedNoise | None = None,
                fold_rows: list[np.ndarray] | None = None) -> float:
    """Return the mean position error (m) of a model on the points of poses it was not fitted to.

    The model (DH errors, tool and instrument frame, plus ``model``'s encoder maps and extension
    terms) is fitted ``folds`` times, each without one fold's poses (:func:`pose_folds`, seed 0;
    the points of one pose, a ``pose`` column or else identical readouts in consecutive rows, stay
    in one fold), and predicts the fold it left out (:func:`validate_points`). The mean is over
    every point of the campaign, each predicted once.

    A fold's points stay in its fit's rows, weighted out (:func:`weighted_out`), so that every
    pose keeps the direction each axis
    moved in to reach it (:attr:`aacmm_pin.model.samples.Samples.direction`, from the sequence of
    readouts, which the arm went through whole): without them the backlash of the WAM's A1 was
    fitted to directions the arm never moved in, and its refit error rose 2.12 -> 2.42 mm where
    with them it falls to 1.85 mm.

    Args:
        campaign: a campaign with absolute points (``points.csv``), shape (N, 3) of them.
        arm: the arm.
        model: the model beyond DH (default: DH).
        folds: number of folds (>= 2).
        noise: the stated noise of every fit (default: the campaign's).
        fold_rows: the rows of each fold instead (e.g. contiguous blocks of the sequence).

    Raises:
        AacmmError: if the campaign has no points, or a fold's fit is refused.
    """
    points = campaign.points
    if points is None:
        raise AacmmError("refit_error: the campaign has no points (points.csv)")
    if fold_rows is None:
        fold_rows = pose_folds(pose_ids(points.q, points.columns.get(POSE_COLUMN)), folds)
    errors = []
    for test in fold_rows:
        if not len(test):
            continue
        cal = identify(weighted_out(campaign, test, noise), arm,
                       model="proposed" if model.map_axes else "dh", use_rtest=model.use_rtest,
                       map_axes=model.map_axes or None, extensions=model.terms, noise=noise)
        held = validate_points(arm, cal.parameters, campaign)  # the whole sequence's directions
        errors.append(np.linalg.norm(held.errors[test], axis=1))
    return float(np.mean(np.concatenate(errors)))


def refit_rule(campaign: Campaign, cal: Calibration, noise: StatedNoise) -> str:
    """Return why discovery checks each step by refits on this campaign, or "" where it does not.

    It does on a campaign of points alone (no SPAT, no length bar: its folds are poses) whose fit
    ``cal`` leaves a residual RMS per coordinate above :data:`REFIT_RATIO` times the stated point
    noise (a ``sigma_um`` column's median, else ``noise.point``).
    """
    points = campaign.points
    if points is None or campaign.spat is not None or campaign.lengthbar is not None:
        return ""
    stated = float(np.median(points.sigma)) if points.sigma is not None else noise.point
    ratio = cal.fit_rms / stated
    if ratio <= REFIT_RATIO:
        return ""
    return (f"the fit's residual ({cal.fit_rms * 1e6:.0f} um per coordinate) is {ratio:.0f}x the "
            f"stated noise ({stated * 1e6:.0f} um), beyond {REFIT_RATIO:g}x: the linearised "
            f"held-out score can be optimistic, so a step is taken only if its {REFIT_FOLDS}-fold "
            f"refit error (each fold's poses predicted by the model fitted without them) falls")
