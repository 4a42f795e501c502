"""The held-out and length-bar confirmations of a discovery candidate (issue 38).

A candidate the F test names is removed only where an independent check contradicts it
(:func:`~aacmm_pin.analyses.linear_scorer.heldout_against`,
:func:`~aacmm_pin.analyses.linear_scorer.bar_against` below ``discovery.CONFIRM``). Each must reject
at about its level where the candidate is as good as nothing (so that where it is real, it costs
at most that much power), rarely where the candidate is real, and often where the check's data
show it is not.
"""

from __future__ import annotations

import numpy as np

from aacmm_pin.analyses.discovery import CONFIRM
from aacmm_pin.analyses.linear_scorer import bar_against, heldout_against

DRAWS = 10_000


def _rejections(p_values: list[float]) -> int:
    return int(np.sum(np.array(p_values) < CONFIRM))


def _binomial_band(p: float) -> float:
    """4 binomial standard deviations of the count of DRAWS events of probability p."""
    return 4 * np.sqrt(DRAWS * p * (1 - p))


def test_heldout_check_rejects_at_its_level_when_the_gains_have_mean_zero() -> None:
    rng = np.random.default_rng(0)
    for groups in (4, 5, 9):  # R-Test locations; 5 folds of points; both
        hits = _rejections([heldout_against(rng.normal(0.0, 3.0, groups)) for _ in range(DRAWS)])
        assert abs(hits - CONFIRM * DRAWS) <= _binomial_band(CONFIRM)


def test_heldout_check_follows_agreeing_groups_not_one_outlier() -> None:
    assert heldout_against(np.array([-20.0, -22.0, -19.0, -21.0])) < CONFIRM  # all groups worse
    assert heldout_against(np.array([12.0, 15.0, 9.0, 14.0])) > 0.99  # all better
    # one left-out location much worse, the others better: no agreement against the candidate
    assert heldout_against(np.array([-207.0, 30.0, 25.0, 40.0])) > CONFIRM
    assert heldout_against(np.array([5.0])) == 1.0  # one group: no spread to judge by
    assert heldout_against(np.zeros(4)) == 1.0


def _bar_draws(t: float, change2: float, fit_chi2: float, rng: np.random.Generator,
               n: int = 6) -> list[float]:
    """p-values of the bar check where the bar holds t of the change b (|b|^2 = change2)."""
    b = np.zeros(n)
    b[0] = np.sqrt(change2)
    out = []
    for _ in range(DRAWS):
        # the SPATs' change is uncertain: the bar holds t of the true change, which is the
        # estimated one scaled by 1 + e, e ~ N(0, 1 / fit_chi2)
        scale = 1.0 + rng.normal(0.0, 1.0 / np.sqrt(fit_chi2))
        a = -t * scale * b + rng.normal(size=n)
        out.append(bar_against(float(a @ a - (a + b) @ (a + b)), change2, fit_chi2))
    return out


def test_bar_check_rejects_at_its_level_where_the_bar_holds_half_the_change() -> None:
    # half the change: the bar's chi-square is as good with it as without, on average
    rng = np.random.default_rng(1)
    for change2, fit_chi2 in ((4.0, 20.0), (30.0, 20.0), (1.0, 200.0)):
        hits = _rejections(_bar_draws(0.5, change2, fit_chi2, rng))
        assert hits <= CONFIRM * DRAWS + _binomial_band(CONFIRM)


def test_bar_check_keeps_a_real_change_and_rejects_one_the_bar_does_not_hold() -> None:
    rng = np.random.default_rng(2)
    # the bar sees the change (60 chi-square units, the SPATs 200): z about +3.4 where it holds
    # all of it, -3.4 (spread 0.88) where it holds none
    real = _rejections(_bar_draws(1.0, 60.0, 200.0, rng))
    assert real <= 0.001 * DRAWS
    absent = _rejections(_bar_draws(0.0, 60.0, 200.0, rng))
    assert absent >= 0.8 * DRAWS
    assert bar_against(-5.0, 0.0, 20.0) == 1.0  # the bar does not see the change
    assert bar_against(-5.0, 4.0, 0.0) == 1.0  # no fit gain: nothing to confirm


def test_groups_that_lose_exactly_alike_speak_against_the_candidate():
    """Held-out gains that do not vary: all equal losses are against it, equal gains are not."""
    assert heldout_against(np.array([-3.0, -3.0, -3.0])) == 0.0
    assert heldout_against(np.array([2.0, 2.0])) == 1.0
    assert heldout_against(np.array([-5.0])) == 1.0  # one group: no test
