"""A simulated humanoid with the traps of a real one (issue 40): two 7-axis arms on a coupled
torso (T4 = -(T2 + T3)), motion capture whose 100 um noise only campaign.json states, the arm's
sizes file, hidden lateral compliance of the torso (an effect not offered by default).

Default ``discover`` (no ``--effects``, no ``sigma_um`` column) must judge against the stated
noise, try the effects not offered by default once the others are exhausted and the residual is
still larger than the noise, name the torso's lateral compliance and end near the noise.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import StatedNoise, write_campaign

TORSO = ("T1", "T2", "T3", "T4")


def humanoid_campaign(folder: Path, seed: int, points: int) -> None:
    """Write the simulated humanoid's campaign (motion capture stated in campaign.json)."""
    arm = ap.load_arm("torso_coupled")
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(
        seed=seed, effects=("dh", "lateral_compliance"), points=points, sigma_point=100e-6))
    write_campaign(replace(sim.campaign, noise=StatedNoise.of_instrument("motion capture")), folder)


def discover_by_default(tmp_path: Path, seed: int, points: int, capsys: pytest.CaptureFixture[str]
                        ) -> tuple[int, dict, str]:
    humanoid_campaign(tmp_path / "camp", seed, points)
    code = main(["discover", str(tmp_path / "camp"), "--arm", "torso_coupled",
                 "--out", str(tmp_path / "out")])
    return code, json.loads((tmp_path / "out" / "discovery.json").read_text()), \
        capsys.readouterr().out


def check(code: int, found: dict, out: str) -> None:
    arm = ap.load_arm("torso_coupled")
    assert code == 0, out
    assert "points 100 um (campaign.json, motion capture)" in out
    assert found["widened"] == ["lateral_compliance"], found["stopped_because"]
    named = {arm.axis_names[a - 1] for step in found["steps"] if step["effect"] ==
             "lateral_compliance" for a in step["axes"]}
    assert named & set(TORSO), found["steps"]
    # ends at the stated noise, or within 10 % of it: a default effect named before the widening
    # (the misspecified model makes one look significant: seed 2 names encoder[A6] at step 2) may
    # stay and leave a few percent (seed 2: 1.05 x, p = 0.004)
    left = found["unexplained"]
    assert left is None or left["noise_ratio"] < 1.1, left
    assert "also tried lateral_compliance (not offered by default)" in out


def test_default_discover_finds_the_humanoids_lateral_compliance(tmp_path, capsys):
    check(*discover_by_default(tmp_path, seed=0, points=300, capsys=capsys))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_default_discover_on_more_humanoids(tmp_path, capsys, seed):
    check(*discover_by_default(tmp_path, seed=seed, points=500, capsys=capsys))
