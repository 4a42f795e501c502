"""What an identification fits (measurements) and the one stated-noise policy (stated_noise)."""

from __future__ import annotations

import dataclasses

import numpy as np

import aacmm_pin as ap
from aacmm_pin.data.campaign import PointLog, StatedNoise
from aacmm_pin.fit.measurements import measurements, stated_noise
from aacmm_pin.units import SIGMA_SOCKET


def _points(arm: ap.Arm, n: int) -> PointLog:
    """n tool points of the nominal arm at random poses, without a sigma_um column."""
    rng = np.random.default_rng(0)
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))
    point = ap.stylus_positions(arm, ap.Parameters.nominal(arm, 5.0), q, frame="mt")
    return PointLog(group=np.ones(n, dtype=np.int64), q=q, point=point)


def test_stated_noise_per_kind_of_sample(arm: ap.Arm, small_sim: ap.Simulation) -> None:
    """SPAT samples get the R-Test's noise, points without sigma_um the instrument's, bar
    readouts the campaign's socket noise, whatever else is fitted beside them."""
    noise = StatedNoise(rtest=1.5e-6, point=7e-6)
    socket = (small_sim.campaign.noise or StatedNoise(socket=SIGMA_SOCKET)).socket
    points = _points(arm, 30)
    spat_points = dataclasses.replace(small_sim.campaign, points=points)
    points_bar = dataclasses.replace(small_sim.campaign, spat=None, locations={}, points=points)
    assert small_sim.campaign.spat is not None and small_sim.campaign.lengthbar is not None
    n_spat, n_bar = len(small_sim.campaign.spat.q), len(small_sim.campaign.lengthbar.q)
    cases = [(small_sim.campaign, False, [(n_spat, noise.rtest)]),
             (small_sim.campaign, True, [(n_spat, noise.rtest), (n_bar, socket)]),
             (spat_points, False, [(n_spat, noise.rtest), (30, noise.point)]),
             (points_bar, True, [(30, noise.point), (n_bar, socket)]),
             (dataclasses.replace(points_bar, lengthbar=None, bar={}), False, [(30, noise.point)])]
    for campaign, use_bar, expected in cases:
        meas = measurements(campaign, arm, True, use_bar)
        want = np.concatenate([np.full(n, value) for n, value in expected])
        np.testing.assert_array_equal(stated_noise(campaign, meas, noise), want)
