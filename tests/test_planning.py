"""Where to measure next: the top-ranked SPAT beats a random candidate once really measured."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aacmm_pin.analyses.planning import Candidate, map_uncertainty, plan
from aacmm_pin.analyses.simulate import SimulationConfig, TrueArm, simulate_campaign, simulate_spat
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import Campaign, SpatLog, write_campaign
from aacmm_pin.fit.identification import identify
from aacmm_pin.model.arm import load_arm


def _with_spat(sim, cand: Candidate, rng: np.random.Generator) -> Campaign:
    """The campaign plus the candidate SPAT measured on the virtual arm (truth), noisy nest."""
    arm = load_arm()
    true_arm = TrueArm(arm, sim.truth, SimulationConfig())
    q, _, disp = simulate_spat(true_arm, cand.location_mt, len(cand.postures), rng,
                               starts=cand.starts)
    spat, new = sim.campaign.spat, max(sim.campaign.locations) + 1
    locations = dict(sim.campaign.locations)
    locations[new] = cand.location_mt + rng.normal(0.0, 3e-6, 3)
    return Campaign(spat=SpatLog(location=np.concatenate([spat.location, np.full(len(q), new)]),
                                 q=np.vstack([spat.q, q]),
                                 displacement=np.vstack([spat.displacement, disp])),
                    locations=locations, lengthbar=None, bar={})


@pytest.mark.parametrize("seed", [0, *(pytest.param(s, marks=pytest.mark.slow) for s in (2, 4))])
def test_top_ranked_spat_beats_a_random_candidate(seed):
    """Adding the first-ranked SPAT shrinks the worst-axis map uncertainty more than a random one."""
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=seed, samples_per_location=100,
                                                  bar_placements=0))
    cal = identify(sim.campaign, arm)
    centre = np.mean(list(sim.campaign.locations.values()), axis=0)
    grid = centre + np.array([[dx, dy, dz] for dz in (0.0, 0.25) for dx in (-0.26, 0.26)
                              for dy in (-0.26, 0.26)])
    result = plan(cal, sim.campaign, grid=grid, seed=seed)
    rng = np.random.default_rng(seed)
    top = result.candidates[0]
    other = result.candidates[1 + rng.integers(len(result.candidates) - 1)]
    after = []
    for cand in (top, other):
        camp = _with_spat(sim, cand, np.random.default_rng(seed + 99))
        after.append(map_uncertainty(identify(camp, arm), camp)[result.worst_axis])
    print(f"seed {seed}: worst A{result.worst_axis} {result.map_std[result.worst_axis]:.3g} rad; "
          f"top ({top.family}) -> {after[0]:.3g}, random ({other.family}) -> {after[1]:.3g}")
    assert after[0] < after[1]
    assert after[0] < result.map_std[result.worst_axis]


def test_plan_cli_lists_ranked_candidates(tmp_path, capsys):
    """`aacmm-pin plan` prints the worst ranges and ranked candidates and writes plan.json."""
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=1, samples_per_location=80,
                                                  samples_per_socket=4, bar_placements=2))
    write_campaign(sim.campaign, tmp_path / "c")
    assert main(["plan", str(tmp_path / "c"), "--grid", "2", "--postures", "20",
                 "--json", str(tmp_path / "plan.json")]) == 0
    out = capsys.readouterr().out
    assert "worst axis" in out and "rank" in out
    data = json.loads((tmp_path / "plan.json").read_text())
    after = [c["worst_axis_std_after_arcsec"] for c in data["candidates"]]
    assert after == sorted(after) and data["length_std_um"] is not None


def test_a_single_worst_node_prints_as_one_angle() -> None:
    """One map node above half the axis max was printed "-150..-150 deg" (issue 26, item 9)."""
    from aacmm_pin.analyses.planning import Plan, _worst_ranges
    from aacmm_pin.units import ARCSEC

    nodes = np.arange(-180.0, 180.0, 30.0)
    std = np.full(nodes.size, 1.0) * ARCSEC
    std[nodes == -150] = 5.0 * ARCSEC  # one node alone
    std[(nodes >= 30) & (nodes <= 90)] = 4.0 * ARCSEC  # a run of three
    ranges = _worst_ranges(std, nodes)
    assert sorted((lo, hi) for lo, hi, _ in ranges) == [(-150.0, -150.0), (30.0, 90.0)]
    text = Plan(worst_axis=2, map_std={2: float(std.mean())}, worst_ranges={2: ranges},
                length_std=None).table()
    assert "-150 deg (5.0 arcsec)" in text and "30..90 deg (4.0 arcsec)" in text, text
    assert "..-150" not in text


def test_candidate_grid_is_the_square_around_the_nests_at_each_height() -> None:
    """The grid the CLI and plan's default share: per_side**2 nests a height, centred, ordered."""
    from aacmm_pin.analyses.planning import candidate_grid

    nests = {1: np.array([0.5, 0.1, 0.0]), 2: np.array([0.7, -0.3, 0.02])}
    spat = SpatLog(location=np.array([1, 2]), q=np.zeros((2, 7)), displacement=np.zeros((2, 3)))
    campaign = Campaign(spat=spat, locations=nests, lengthbar=None, bar={})
    centre = np.mean(list(nests.values()), axis=0)
    grid = candidate_grid(campaign, 4, 0.3, (0.0, 0.1, 0.25))
    assert grid.shape == (4 * 4 * 3, 3)
    assert np.allclose(grid[:16].mean(axis=0), centre, rtol=0, atol=1e-15)
    assert np.allclose(grid[:, :2].min(axis=0), centre[:2] - 0.3, rtol=0, atol=1e-15)
    assert np.allclose(grid[:, :2].max(axis=0), centre[:2] + 0.3, rtol=0, atol=1e-15)
    assert np.allclose(np.unique(grid[:, 2]) - centre[2], [0.0, 0.1, 0.25], rtol=0, atol=1e-15)
    assert (np.diff(grid[:, 2]) >= 0).all()  # by height first, then x, then y
    assert np.array_equal(candidate_grid(campaign, 1), centre + [[0, 0, 0], [0, 0, 0.25]])
    default = candidate_grid(campaign)  # plan's default: 3 x 3, 260 mm, table and 250 mm above
    offsets = np.array([[dx, dy, dz] for dz in (0.0, 0.25) for dx in (-0.26, 0.0, 0.26)
                        for dy in (-0.26, 0.0, 0.26)])
    assert np.array_equal(default, centre + offsets)  # the same bits as before the grid moved
    steps = np.linspace(-123.4, 123.4, 7) * 1e-3  # the CLI's grid in mm, as it always built it
    cli = np.array([centre + [dx, dy, dz] for dz in (0.0, 0.1) for dx in steps for dy in steps])
    assert np.array_equal(candidate_grid(campaign, 7, 123.4, (0.0, 0.1), unit=1e-3), cli)
