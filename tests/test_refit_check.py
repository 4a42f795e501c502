"""Refits of points campaigns (issue 40): held-out poses kept in the arm's sequence of motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.refit_check import REFIT_RATIO, refit_error, refit_rule, weighted_out
from aacmm_pin.data.campaign import PointLog, StatedNoise
from aacmm_pin.model.samples import Samples

UR5 = Path(__file__).resolve().parents[1] / "urdf" / "ur5.urdf"
SIGMA = 20e-6  # tracker noise per coordinate, m
HALF = 1e-3  # backlash of A1, rad: about 0.4 mm at the tool, 20x the noise
MEAN_NORM = np.sqrt(8 / np.pi)
"""Mean length of a 3D Gaussian error of sigma 1 per coordinate."""


@pytest.fixture(scope="module")
def backlash_campaign() -> tuple[ap.Arm, ap.Campaign]:
    """300 random poses of a UR5 in sequence, backlash on A1, tracker noise."""
    arm = ap.load_arm(UR5)
    rng = np.random.default_rng(7)
    nominal = ap.Parameters.nominal(arm, 5.0)
    truth = nominal.replace(translation=rng.uniform(-2.0, 2.0, 3),
                            extensions={"backlash[A1]": np.array([HALF])})
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (300, arm.n_axes))
    point = (ap.stylus_positions(arm, truth, q, frame="mt", samples=Samples(arm, q))
             + rng.normal(0.0, SIGMA, (300, 3)))
    return arm, ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.ones(300, dtype=np.int64), q=q, point=point),
        noise=StatedNoise(point=SIGMA))


def test_backlash_refits_keep_the_directions_moved_in(backlash_campaign):
    """With the true model (backlash on A1), each fold's poses are predicted to the noise: the
    directions come from the whole sequence (refits of the other poses alone would take them
    from neighbours the arm never moved between); DH misses the backlash."""
    arm, campaign = backlash_campaign
    model = ap.effects.ModelSpec((ap.effects.term_from_key("backlash[A1]"),))
    found, dh = refit_error(campaign, arm, model), refit_error(campaign, arm)
    assert found < 1.2 * MEAN_NORM * SIGMA  # 1.2: 300 poses, 33 parameters
    assert dh > 5 * found


def test_weighted_out_rows_are_not_fitted(backlash_campaign):
    """A fold weighted out keeps its rows (in order) and carries no weight: moving its points by
    1 mm changes the fit by less than a nanometre."""
    arm, campaign = backlash_campaign
    rows = np.arange(0, 300, 5)
    out = weighted_out(campaign, rows)
    assert out.points is not None and campaign.points is not None
    assert np.array_equal(out.points.q, campaign.points.q)
    moved = out.points.point.copy()
    moved[rows] += 1e-3
    shifted = ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, noise=out.noise,
                          points=PointLog(group=out.points.group, q=out.points.q, point=moved,
                                          sigma=out.points.sigma))
    a, b = (ap.identify(c, arm, model="dh").parameters for c in (out, shifted))
    pa, pb = (ap.stylus_positions(arm, p, campaign.points.q, frame="mt") for p in (a, b))
    assert np.abs(pa - pb).max() < 1e-9


def test_refit_rule_follows_the_residual_against_the_stated_noise(backlash_campaign):
    """DH leaves the backlash (residual >10x the noise): refits; the true model does not."""
    arm, campaign = backlash_campaign
    dh = ap.identify(campaign, arm, model="dh")
    true = ap.identify(campaign, arm, model="dh",
                       extensions=(ap.effects.term_from_key("backlash[A1]"),))
    assert dh.fit_rms > REFIT_RATIO * SIGMA and "10x" in refit_rule(campaign, dh, StatedNoise())
    assert refit_rule(campaign, true, StatedNoise()) == ""


def test_a_refit_that_cannot_be_done_stops_the_check_not_discover(backlash_campaign, monkeypatch):
    """Where a fold's fit is refused (e.g. an instrument group left with too few rows), discover
    goes on with the linearised scores and says that the refit check stopped."""
    from aacmm_pin.analyses import discovery
    from aacmm_pin.errors import AacmmError

    def refused(*args, **kwargs):
        raise AacmmError("the points of group 2 lie on a line")

    monkeypatch.setattr(discovery, "refit_error", refused)
    arm, campaign = backlash_campaign
    result = ap.discover(campaign, arm, start="dh", max_steps=1)
    assert "refits stopped" in result.refit_rule and "group 2" in result.refit_rule
    assert result.refit_errors == []
