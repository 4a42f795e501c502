"""Uncertainty and planning of a calibration whose terms read per-sample columns.

The built-in thermal term reads ``temp_c``, the example stylus plugin
(``examples/07_stylus_plugin``) ``temp_probe_c``: the length bar's Jacobian (linearised length
std, :func:`~aacmm_pin.analyses.uncertainty.monte_carlo`) and the plan's SPATs, bar and planned
postures (:func:`~aacmm_pin.analyses.planning.plan`) read them too. Checked: the bar's points of
the uncertainty's Jacobian are those ``validate`` predicts from the bar's own columns; Monte Carlo
gives each term's standard uncertainty, which agrees with the fit's covariance and covers the
hidden truth; ``plan`` ranks candidates.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.planning import candidate_grid, plan, planned_conditions
from aacmm_pin.analyses.uncertainty import length_jacobian, monte_carlo
from aacmm_pin.analyses.validation import validate
from aacmm_pin.effects import registry, thermal
from aacmm_pin.effects.calibrated import held_columns, stylus_positions
from tests.helpers import ROOT

PLUGIN = ROOT / "examples" / "07_stylus_plugin" / "aacmm_pin_stylustemp.py"
ALPHA = 11e-6
"""The simulator's thermal expansion (``SimulationConfig.thermal_alpha``), 1/K."""
STYLUS = "stylus_thermal[stylus]"
"""The plugin's term on the default arm's tool: hidden value 0 (the stylus does not grow)."""


@pytest.fixture(scope="module")
def thermal_cal(arm: ap.Arm) -> Iterator[tuple[ap.Campaign, ap.Calibration]]:
    """A campaign warming 20-24 deg C (4 x 40 SPATs, 2 bar placements) whose stylus temperature
    (``temp_probe_c``) ramps 20-30 deg C, identified with the thermal and the plugin's term."""
    before = dict(registry.LIBRARY)
    registry.load_effect_file(PLUGIN)
    try:
        sim = ap.simulate_campaign(arm, ap.SimulationConfig(
            seed=0, effects=("dh", "encoder", "rtest", "thermal"), samples_per_location=40,
            bar_placements=2, samples_per_socket=5))
        campaign = sim.campaign
        assert campaign.spat is not None and campaign.lengthbar is not None
        parts = {name: replace(log, columns={**log.columns,
                                             "temp_probe_c": np.linspace(20.0, 30.0, len(log.q))})
                 for name, log in (("spat", campaign.spat), ("lengthbar", campaign.lengthbar))}
        campaign = replace(campaign, **parts)
        terms = (thermal(), registry.term_from_key(STYLUS))
        yield campaign, ap.identify(campaign, arm, "proposed", extensions=terms)
    finally:
        registry.LIBRARY.clear()
        registry.LIBRARY.update(before)


def test_the_bar_jacobian_reads_the_bars_columns(arm: ap.Arm, thermal_cal) -> None:
    """The length errors beside the bar's Jacobian are validate's (the bar's temperatures)."""
    campaign, cal = thermal_cal
    errors, grads = length_jacobian(cal, campaign)
    np.testing.assert_allclose(errors, validate(arm, cal.parameters, campaign).errors,
                               rtol=0, atol=1e-12)  # m: the same model, floating point apart
    assert np.all(np.isfinite(grads)) and np.abs(grads).max() > 0


def test_monte_carlo_gives_each_terms_uncertainty(thermal_cal) -> None:
    """Each term's Monte Carlo std agrees with the covariance's within what 20 trials resolve,
    and the hidden values (11 ppm/K, a stylus that does not grow) lie within 3 std.

    (Seeds 0-3 of this campaign with the thermal term alone: alpha 10.74-11.17 ppm/K, linearised
    std 0.28-0.44, Monte Carlo 0.30-0.32 ppm/K.)
    """
    campaign, cal = thermal_cal
    mc = monte_carlo(cal, campaign, 20, workers=1)
    assert mc.length_std is not None and mc.length_linear_std is not None
    assert np.all(mc.length_linear_std > 0)
    for name, truth in (("thermal.alpha", ALPHA), (f"{STYLUS}.k", 0.0)):
        i = mc.names.index(name)
        assert mc.identifiable[i], name
        assert abs(mc.std[i] / mc.linear_std[i] - 1) <= mc.agree_limit, (name, mc.std[i],
                                                                       mc.linear_std[i])
        assert abs(cal.x[i] - truth) <= 3 * mc.linear_std[i], (name, cal.x[i], mc.linear_std[i])


def test_plan_ranks_candidates(arm: ap.Arm, thermal_cal) -> None:
    """plan works on the calibration: its SPATs, bar and planned postures read the columns; a
    planned posture puts the stylus on its nest at the campaign's median conditions (22 deg C:
    about 20 um from where the arm at 20 deg C would put it)."""
    campaign, cal = thermal_cal
    grid = candidate_grid(campaign, 2, 260.0, [0.0], unit=1e-3)
    result = plan(cal, campaign, grid=grid, n_postures=20, families="any", seed=0)
    assert result.candidates and result.length_std is not None
    assert all(c.worst_after < result.map_std[result.worst_axis] for c in result.candidates)
    conditions = planned_conditions(campaign)
    assert conditions.keys() == {"t_s", "temp_c", "temp_probe_c"}
    for c in result.candidates:
        at = held_columns(arm, c.postures, conditions)
        reached = stylus_positions(arm, cal.parameters, c.postures, frame="mt", samples=at)
        np.testing.assert_allclose(reached, np.tile(c.location_mt, (len(c.postures), 1)),
                                   rtol=0, atol=1e-9)  # m: IK to 1e-12 m, two models' rounding
