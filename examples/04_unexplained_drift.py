"""Say where model and data disagree when no effect of the library explains it, then add your own.

Simulates a campaign (4 R-Test locations x 100 SPAT samples, 2 s apart, a ``t_s`` column) of the
paper's model (DH errors, encoder errors, the sphere moving in its seat) whose R-Test fixture creeps
a few micrometres, linearly in time, while each location is measured: an effect the library does
not have. :func:`aacmm_pin.discover` names nothing, but its residual scan reports the final residual
as *unexplained* (larger than the stated 2 um R-Test noise and following time). The script then
registers a small user effect with :func:`aacmm_pin.effects.register_effect`: one
:class:`~aacmm_pin.effects.MeasurementTerm` whose basis is the time since the location's first
sample, per coordinate
(the fixture's creep rate), reruns discovery, which names it, and prints the held-out gap before
and after. Writes both runs' ``discovery.json`` and figures (``discovery_unexplained.png``: the
residual against time) in ``--out``. Exits with status 1 if the creep is not reported first, not
named on the rerun, or something is still unexplained.

Run: ``python examples/04_unexplained_drift.py [--out DIR]`` (about 5 s;
default DIR: ``examples/out/unexplained-example``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from aacmm_pin import SimulationConfig, discover, load_arm, simulate_campaign, write_discovery
from aacmm_pin.effects import Effect, MeasurementTerm, Term, register_effect
from aacmm_pin.effects.base import TIME_WITHIN_LOCATION
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.samples import Samples

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "out" / "unexplained-example"),
                    help="output folder (default: examples/out/unexplained-example)")
parser.add_argument("--creep-um", type=float, default=4.0,
                    help="creep of the fixture over one location, um")
args = parser.parse_args()
out = Path(args.out)

# 1. a campaign with an effect outside the library: the fixture creeps during every location
arm = load_arm()
campaign = simulate_campaign(arm, SimulationConfig(seed=7, samples_per_location=100,
                                                   bar_placements=0)).campaign
spat = campaign.spat
assert spat is not None
t = np.arange(len(spat.location)) * 2.0  # s
direction = np.array([0.6, -0.3, 0.74]) / np.linalg.norm([0.6, -0.3, 0.74])
displacement = np.array(spat.displacement)
for m in np.unique(spat.location):
    sel = spat.location == m
    since = t[sel] - t[sel].min()
    displacement[sel] += np.outer(since / since.max(), direction) * args.creep_um * 1e-6
campaign = campaign.with_spat(t=t, displacement=displacement)
print(f"simulated 4 SPATs of 100 samples, the fixture creeping {args.creep_um:g} um over each "
      "location; discovering with the library alone ...", flush=True)

# 2. discovery with the library alone: nothing to name, but the residual says where it disagrees
first = discover(campaign, arm, start="proposed")
write_discovery(first, arm, out / "library")
print(f"library only: named {first.named or 'nothing'}; held-out RMS "
      f"{first.heldout_rms[-1] * 1e6:.2f} um, fit RMS {first.fit_rms[-1] * 1e6:.2f} um")
report = first.unexplained
print(f"  unexplained: {'null' if report is None else report['hint']}")


# 3. the user's own effect: the fixture creeps linearly in time within each location
def creep_basis(samples: Samples) -> np.ndarray:
    """Change of the measured point per creep rate (m/s), shape (N, 3, 3): time in location."""
    out = np.zeros((samples.n, 3, 3))
    for c in range(3):
        out[:, c, c] = samples.time_in_location()
    return out


def creep_variable(samples: Samples) -> tuple[str, np.ndarray]:
    """Time since the location's first sample (figures)."""
    return "time within its location (s)", samples.time_in_location()


def fixture_creep() -> Term:
    """The fixture creeps at a constant rate per coordinate while a location is measured."""
    return MeasurementTerm("fixture_creep", "fixture_creep",
                           ("fixture_creep.vx", "fixture_creep.vy", "fixture_creep.vz"), (2e-8,) * 3,
                           "the R-Test fixture creeps at a constant rate while each location is "
                           "measured", follows=(TIME_WITHIN_LOCATION,),
                           basis_of=creep_basis, variable_of=creep_variable)


class FixtureCreep(Effect):
    """The R-Test fixture creeps in time within each location."""

    name = "fixture_creep"
    description = "the R-Test fixture creeps in time within each location"
    reads = ("t_s",)

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        return [fixture_creep()] if samples.t is not None else []

    def term(self, key: str) -> Term | None:
        return fixture_creep() if key == "fixture_creep" else None


register_effect(FixtureCreep)

# 4. rerun: discovery names the creep and the held-out gap shrinks
second = discover(campaign, arm, start="proposed")
write_discovery(second, arm, out / "with_creep")
for step in second.steps:
    print(f"with fixture_creep registered: named {step.effect}: held-out RMS "
          f"{step.heldout_rms_before * 1e6:.2f} -> {step.heldout_rms_after * 1e6:.2f} um, fit RMS "
          f"{step.fit_rms_before * 1e6:.2f} -> {step.fit_rms_after * 1e6:.2f} um")
rate = second.calibration.parameters.extensions.get("fixture_creep")
if rate is not None:
    found = np.asarray(rate) * 200.0 * 1e6  # over one location (100 samples x 2 s)
    print(f"  creep over one location: identified {np.array2string(found, precision=2)} um, "
          f"true {np.array2string(direction * args.creep_um, precision=2)} um")
after = second.unexplained
print(f"  unexplained: {'null' if after is None else after['hint']}")
print(f"wrote {out / 'library'} and {out / 'with_creep'}")

top = None if report is None or not report["structure"] else report["structure"][0]["variable"]
ok = top == "time" and ("fixture_creep", []) in second.named and after is None
sys.exit(0 if ok else 1)
