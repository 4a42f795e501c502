"""Discovery time: one `discover` against one `identify` of its start model on the same campaign.

Run: ``python benchmarks/discover.py`` (a minute or two; writes its section of BENCHMARKS.md).
Paper-sized campaigns (4 locations x 200 SPAT samples, 7 bar placements, seed 0): the proposed
start on a campaign with gravity compliance added to the default effects, the DH start on the
default effects (DH, encoder, R-Test). Median and range of 7 rounds (CPU), each round one
discover and the mean of 3 identifies (the identify from DH takes 0.1 s: one call alone is as
noisy as the machine), identify and discover alternating; the ratio's range is over the rounds.
The baseline is a unit of cost (one identify of the start model, same process, same campaign),
not another way to discover: the ratio says how many identifies a discovery costs.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import discover, identify, load_arm, simulate_campaign  # noqa: E402
from aacmm_pin.analyses.simulate import DEFAULT_EFFECTS, SimulationConfig  # noqa: E402
from benchmarks._report import machine, ratio, write_section  # noqa: E402

REPEAT = 7
"""Rounds: each one discover and IDENTIFY_CALLS identifies."""
IDENTIFY_CALLS = 3
"""Identifies per round, their mean the round's identify time."""
SPREAD = 1.5
"""Max/min time ratio above which the section notes the spread (a busy machine)."""


def timed(f):
    """Return the CPU time of one call (this process) and its result."""
    tic = time.process_time()
    out = f()
    return time.process_time() - tic, out


def bar(values: list[float | None]) -> str:
    """Return the normalised length-bar error of the start and final models."""
    if values[0] is None or values[-1] is None:
        return "-"
    return f"{values[0]:.2f} -> {values[-1]:.2f}"


def main() -> None:
    arm = load_arm()
    cases = [("proposed", "default + compliance", (*DEFAULT_EFFECTS, "compliance")),
             ("dh", "default (dh, encoder, rtest)", DEFAULT_EFFECTS)]
    rows, spread = [], []
    for start, label, effects in cases:
        camp = simulate_campaign(arm, SimulationConfig(seed=0, effects=effects,
                                                       samples_per_location=200)).campaign
        identify(camp, arm, model=start)  # warm-up
        t_id, t_disc, result = [], [], None
        for _ in range(REPEAT):
            dt, _cal = timed(lambda: [identify(camp, arm, model=start)
                                      for _ in range(IDENTIFY_CALLS)])
            t_id.append(dt / IDENTIFY_CALLS)
            dt, result = timed(lambda: discover(camp, arm, start=start))
            t_disc.append(dt)
        for name, times in (("identify", t_id), ("discover", t_disc)):
            if max(times) / min(times) > SPREAD:
                spread.append(f"{name} from `{start}`: {min(times):.2f} to {max(times):.2f} s")
        named = ", ".join(f"{s.effect} ({', '.join(f'A{a}' for a in s.axes) or 'arm-wide'})"
                          for s in result.steps) or "nothing"
        med_id, med_disc = float(np.median(t_id)), float(np.median(t_disc))
        rows.append(f"| `{start}` | {label} | {med_id:.2f} ({min(t_id):.2f} - {max(t_id):.2f}) | "
                    f"{med_disc:.2f} ({min(t_disc):.2f} - {max(t_disc):.2f}) | "
                    f"{ratio(t_disc, t_id, '.1f', name=f'discover / identify, {start}')} | "
                    f"{len(result.steps)} | "
                    f"{sum(result.n_candidates)} ({' + '.join(map(str, result.n_candidates))}) | "
                    f"{named} | {result.heldout_rms[0] * 1e6:.2f} -> "
                    f"{result.heldout_rms[-1] * 1e6:.2f} | {bar(result.bar_normalised)} |")
    note = ("" if not spread else
            "\n\nLarge spread between the runs (max/min > " + f"{SPREAD}" + "; the 2 cores may have "
            "been shared with another process): " + "; ".join(spread) + ".")
    table = "\n".join(rows)
    body = f"""## Discovery (`python benchmarks/discover.py`)

{machine()}. Simulated paper-sized campaigns (4 locations x 200 SPAT samples, 7 length-bar
placements, seed 0). Baseline: one `identify` of the start model (`model=start`, with the R-Test)
on the same campaign; `discover(campaign, arm, start=...)` fits the start model, scores every
candidate term of the effect library on held-out data (left-out locations and the length bar),
refits with each named effect and stops when nothing is significant (times include the length-bar
linearisation of every model). CPU time (the 2 cores are shared), median (range) of {REPEAT}
rounds, each one `discover` and the mean of {IDENTIFY_CALLS} `identify` calls, alternating; the
ratio's range is over the rounds of this run and of the earlier runs named below. The baseline
is a unit of cost, not another way to discover: the
ratio says how many identifies of the start model a discovery costs.
Last column: the length-bar error
normalised by its predicted covariance (final model's), start -> final.

| start | simulated effects | identify (s) | discover (s) | discover / identify | steps | \
candidates scored (per step) | named | held-out RMS (um) | bar, normalised |
|---|---|---|---|---|---|---|---|---|---|
{table}{note}"""
    write_section("discover", body)


if __name__ == "__main__":
    main()
