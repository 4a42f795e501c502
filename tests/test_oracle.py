"""Discovery against the oracle (issue 27, items 1-2): at the size where the likelihood-ratio test
that knows the effect's exact form finds it 9 times in 10 (level 0.01), the goal is that discovery
finds it >= 8 in 10 (library effects) or says "unexplained" with the right variable first >= 7 in
10 (out of the library), with no alarm on >= 95 % of null campaigns (40 seeds per start, :data:`NULL_SEEDS`).

What is checked to pass: the oracle's counted power matches its prediction; on library effects
discovery is not below the power of the same test searching the first step's m candidates at
discovery's search level (``ALPHA`` / m, Bonferroni; ``ALPHA`` its search's share of the 1 %
family-wise false-alarm rate), i.e. it loses nothing but the search; the null
campaigns. The goal itself is reported as an expected failure where it is not met: a search over
m = 24 candidates has power 0.40 at that size at ``ALPHA`` = 1e-3, 0.62 with the whole 1 %
family-wise rate (issue 38's searching oracle) and 0.78 even with a 0.05 false-alarm budget
(one-parameter effect, 860 degrees of freedom; see BENCHMARKS.md).

The harness is ``benchmarks/oracle.py`` (its table: ``python benchmarks/oracle.py``); campaigns of
4 x 100 SPAT samples, so that a seed costs about 2 s of CPU.
"""

from __future__ import annotations

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.false_alarm import FalseAlarm
from benchmarks.oracle import (
    CASES,
    NULL_SEEDS,
    ORACLE_LEVEL,
    discovery_right,
    false_alarms,
    oracle_power,
    run,
    size_at_power,
)

SEEDS = range(10)
ALPHA = FalseAlarm().search
"""Discovery's search share of its family-wise false-alarm rate (Bonferroni over the candidates)."""


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_discovery_power_near_the_oracle(arm: ap.Arm, case) -> None:
    size, absorbed = size_at_power(case, arm, 0.9)
    runs = [run(case, arm, seed, size) for seed in SEEDS]
    right = sum(discovery_right(case, result) for result, _ in runs)
    # the oracle's own power on these campaigns: counted, against its prediction (binomial spread)
    predicted = float(np.mean([oracle_power(o.noncentrality, o.k, o.dof) for _, o in runs]))
    counted = sum(o.p_value < ORACLE_LEVEL for _, o in runs)
    m = int(np.median([result.n_candidates[0] for result, _ in runs]))
    searched = float(np.mean([oracle_power(o.noncentrality, o.k, o.dof, ALPHA / m)
                              for _, o in runs]))
    n = len(runs)
    print(f"{case.name}: size {size / case.scale:.3g} {case.unit}, absorbed {absorbed:.0%}, "
          f"oracle {counted}/{n} (predicted {predicted:.2f}), searching {m} at {ALPHA:g}: "
          f"{searched:.2f}, discovery {right}/{n}")

    def spread(p: float) -> float:  # 3 binomial standard deviations, plus one count
        return 3 * np.sqrt(p * (1 - p) * n) + 1

    assert abs(counted - predicted * n) <= spread(predicted)
    if case.library:
        assert right >= searched * n - spread(searched)
    goal = 0.8 if case.library else 0.7
    if right < goal * n:
        pytest.xfail(f"{case.name}: discovery {right}/{n} at the oracle's 0.9 size, goal {goal}; "
                     f"a search over {m} candidates at {ALPHA:g}: {searched:.2f}")


@pytest.mark.slow
@pytest.mark.parametrize("start", ["dh", "proposed"])
def test_no_false_alarm_on_null_campaigns(arm: ap.Arm, start: str) -> None:
    case = next(c for c in CASES if c.start == start)
    hits, n = false_alarms(case, arm, NULL_SEEDS)
    print(f"{start}: {hits}/{n} false alarms")
    assert n >= 20 and hits <= 0.05 * n
