"""Monte Carlo throughput: trials per second, serial and with 2 local worker processes.

Run: ``python benchmarks/uncertainty.py`` (about a minute; writes its section of BENCHMARKS.md).
Each trial perturbs the R-Test readings (2 um) and nest positions (3 um) of the paper-sized
campaign (1,600 samples) and re-identifies from the nominal solution (`aacmm_pin.fit.identification.refit`).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import identify, load_arm, simulate_campaign  # noqa: E402
from aacmm_pin.analyses.simulate import SimulationConfig  # noqa: E402
from aacmm_pin.analyses.uncertainty import monte_carlo  # noqa: E402
from benchmarks._report import machine, write_section  # noqa: E402


def main() -> None:
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=0, samples_per_location=400))
    cal = identify(sim.campaign, arm)
    rows = []
    for workers, trials in ((1, 100), (2, 100)):
        tic = time.perf_counter()
        mc = monte_carlo(cal, sim.campaign, trials, workers=workers, seed=1)
        dt = time.perf_counter() - tic
        rows.append((workers, trials, dt, mc.converged))
    base = rows[0][1] / rows[0][2]
    table = "\n".join(f"| {w} | {n} | {dt:.1f} | {n / dt:.1f} | {n / dt / base:.2f}x | {ok} |"
                      for w, n, dt, ok in rows)
    write_section("uncertainty", f"""## Monte Carlo throughput (`python benchmarks/uncertainty.py`)

{machine()}. Proposed model with the R-Test, paper-sized campaign (1,600 samples, {len(cal.x)}
unknowns); each trial re-identifies a perturbed campaign from the nominal solution. Times include
the validation of every trial on the length bar (7 placements x 3 sockets x 40 postures) and, for
2 workers, starting the processes and shipping the problem to them.

| workers | trials | time (s) | trials/s | vs serial | converged |
|---|---|---|---|---|---|
{table}""")


if __name__ == "__main__":
    main()
