"""Monte Carlo throughput: trials per second, serial and with 2 local worker processes.

Run: ``python benchmarks/uncertainty.py`` (about a minute; writes its section of BENCHMARKS.md).
Each trial perturbs the R-Test readings (2 um) and nest positions (3 um) of the paper-sized
campaign (1,600 samples) and re-identifies from the nominal solution (`aacmm_pin.fit.identification.refit`).
A throughput: the baseline is the same trials in this process (``workers=1``); there is no
independent implementation to compare with. Wall time (the speed-up of 2 processes shows only
there), rounds interleaved (serial, then 2 workers), the speed-up's range over the rounds.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import identify, load_arm, simulate_campaign  # noqa: E402
from aacmm_pin.analyses.simulate import SimulationConfig  # noqa: E402
from aacmm_pin.analyses.uncertainty import monte_carlo  # noqa: E402
from benchmarks._report import machine, ratio, spread, write_section  # noqa: E402

TRIALS = 100
ROUNDS = 5
"""Interleaved rounds (each: serial, then 2 workers); the speed-up's range is over them."""


def main() -> None:
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=0, samples_per_location=400))
    cal = identify(sim.campaign, arm)
    walls: dict[int, list[float]] = {1: [], 2: []}
    converged: dict[int, list[int]] = {1: [], 2: []}
    loads = [os.getloadavg()[0]]
    for _ in range(ROUNDS):
        for workers in (1, 2):
            tic = time.perf_counter()
            mc = monte_carlo(cal, sim.campaign, TRIALS, workers=workers, seed=1)
            walls[workers].append(time.perf_counter() - tic)
            converged[workers].append(int(mc.converged))
        loads.append(os.getloadavg()[0])
    serial = np.array(walls[1])
    rows = []
    for workers in (1, 2):
        w = np.array(walls[workers])
        rows.append(f"| {workers} | {TRIALS} | {spread(w, '.1f')} | {spread(TRIALS / w, '.1f')} | "
                    f"{'1x' if workers == 1 else ratio(serial, w, '.2f', name=f'{workers} workers')} | "
                    f"{min(converged[workers])} |")
    table = "\n".join(rows)
    write_section("uncertainty", f"""## Monte Carlo throughput (`python benchmarks/uncertainty.py`)

{machine()}. Proposed model with the R-Test, paper-sized campaign (1,600 samples, {len(cal.x)}
unknowns); each trial re-identifies a perturbed campaign from the nominal solution. Times include
the validation of every trial on the length bar (7 placements x 3 sockets x 40 postures) and, for
2 workers, starting the processes and shipping the problem to them. A throughput with no
independent implementation to compare with: the baseline is the same trials in one process.
Wall time (a speed-up from 2 processes shows only there), median (range) of {ROUNDS} interleaved
rounds (serial, then 2 workers); the speed-up's range is over the rounds of this run and of the
earlier runs named below (per round: serial
wall over 2 workers' wall). The load average (1 min) went {min(loads):.1f} - {max(loads):.1f}
during the rounds: with other jobs on the 2 cores the second worker gains less.

| workers | trials | wall (s) | trials/s | vs serial | converged (fewest of the rounds) |
|---|---|---|---|---|---|
{table}""")


if __name__ == "__main__":
    main()
