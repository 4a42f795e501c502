"""Lateral compliance end to end: the gravity moments, the term, the simulator and discovery on the torso."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin
import pytest

import aacmm_pin as ap
from aacmm_pin import cli
from aacmm_pin import effects as fx
from aacmm_pin.analyses.discovery import discover
from aacmm_pin.analyses.linear_scorer import LinearScorer
from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.effects.registry import terms_of
from aacmm_pin.fit.identification import measurements
from aacmm_pin.model._chain import BatchedChain
from aacmm_pin.model.samples import Samples

ROOT = Path(__file__).resolve().parents[1]
TORSO = ROOT / "urdf" / "torso.urdf"
HIDDEN = {1: (3e-5, 2e-5), 3: (2e-5, 4e-5), 10: (4e-5, 3e-5)}
"""Hidden lateral compliance (kx, ky), rad/(N m): the torso axis T1 and the shoulder pitch of each
arm (L2 = A3, R2 = A10), 0.4 mm RMS (1.8 mm at most) at the markers under their 10-40 N m."""
POINTS = 1000
"""Motion-capture poses, a marker on each hand measured alternately (500 each)."""
SIGMA = 1e-4
"""Motion-capture noise per coordinate, m (0.1 mm: markers in a calibrated volume)."""


def _config(seed: int, hidden: dict[int, tuple[float, float]] = HIDDEN) -> SimulationConfig:
    """A humanoid's DH errors (0.3 mm, 0.03 deg), the hidden lateral compliance, mocap points."""
    return SimulationConfig(seed=seed, effects=("dh", "lateral_compliance"), points=POINTS,
                            sigma_point=SIGMA, dh_sigma_length=3e-4,
                            dh_sigma_angle=np.radians(0.03), lateral_compliance=hidden)


@pytest.fixture(scope="module")
def torso() -> ap.Arm:
    return ap.load_arm(TORSO)


# ------------------------------------------------------------------------------ the moments
def test_lateral_gravity_is_pinocchios_rnea_moment_in_the_joint_basis(torso: ap.Arm) -> None:
    """Samples.lateral_gravity is minus RNEA's transmitted moment (at rest) on the x, y columns of
    each joint's basis, whose z column gives Samples.gravity (minus the generalized gravity)."""
    rng = np.random.default_rng(2)
    q = rng.uniform(-1.5, 1.5, (20, torso.n_axes))
    samples = Samples(torso, q)
    model = torso.runtime_model()
    data, chain = model.createData(), BatchedChain(model)
    ids = [model.getJointId(n) for n in torso.axis_names]
    for i, qi in enumerate(q):
        full = np.zeros(model.nq)
        full[[model.joints[j].idx_q for j in ids]] = qi
        pin.rnea(model, data, full, np.zeros(model.nv), np.zeros(model.nv))
        moment = np.array([-chain.basis(j).T @ data.f[j].angular for j in ids])  # (n_axes, 3)
        np.testing.assert_allclose(samples.lateral_gravity[i], moment[:, :2], atol=1e-12)
        np.testing.assert_allclose(samples.gravity[i], moment[:, 2], atol=1e-12)
    assert samples.lateral_gravity.shape == (20, torso.n_axes, 2)
    assert np.abs(samples.lateral_gravity[:, 0]).max() > 10.0  # the torso carries both arms


# ------------------------------------------------------------------------------ the effect
def test_term_keys_variables_and_candidates(torso: ap.Arm) -> None:
    """One term per axis, two parameters, parsed back from its key; the scan's variables are the
    moments' components; tried by discovery only when named."""
    term = fx.term_from_key("lateral_compliance[A3]")
    assert isinstance(term, fx.TiltTerm) and term == fx.lateral_compliance(3)
    assert term.names == ("lateral_compliance[A3].kx", "lateral_compliance[A3].ky")
    assert term.follows == ("the lateral gravity torque on A3 (x)",
                            "the lateral gravity torque on A3 (y)")
    assert term.sizes(torso.sizes).tolist() == [3e-5, 3e-5]  # urdf/torso.sizes.json
    assert term.sizes(ap.load_arm().sizes).tolist() == [1e-5, 1e-5]  # the default
    samples = Samples(torso, np.random.default_rng(0).uniform(-1.5, 1.5, (50, torso.n_axes)))
    effect = fx.library()["lateral_compliance"]
    assert [t.axes[0] for t in effect.candidates(torso, samples)] == list(range(1, 16))
    names = [v.name for v in effect.variables(torso, samples)]
    assert "the lateral gravity torque on A3 (x)" in names and len(names) >= 20
    assert not effect.by_default and "lateral_compliance" not in fx.registry.default_effects()
    basis = term.basis(samples)
    np.testing.assert_array_equal(basis[:, 0, 0], samples.lateral_gravity[:, 2, 0])
    np.testing.assert_array_equal(basis[:, 1, 1], samples.lateral_gravity[:, 2, 1])
    assert not basis[:, 0, 1].any() and not basis[:, 1, 0].any()


def test_runtime_and_identification_models_agree_on_a_tree(torso: ap.Arm) -> None:
    """predict (runtime model) and stylus_positions (identification model) with lateral
    compliance on the torso and both arms agree to 1e-12 m, and the tilt moves the points."""
    truth = simulate_campaign(torso, _config(0)).truth
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.5, 1.5, (40, torso.n_axes))
    tool = np.where(np.arange(40) % 2, "right", "left")
    runtime = ap.predict(torso, truth, q, tool=tool)
    ident = stylus_positions(torso, truth, q, frame="r", tool=tool)
    np.testing.assert_allclose(runtime, ident, atol=1e-12)
    plain = stylus_positions(torso, truth.replace(extensions={}), q, frame="r", tool=tool)
    assert np.abs(ident - plain).max() > 1e-4


# ------------------------------------------------------------------------------ the simulator
def test_simulated_points_follow_the_truths_extensions(torso: ap.Arm, tmp_path: Path) -> None:
    """The simulator holds the hidden lateral compliance as extension terms of the truth and its
    true points are the model's own (stylus_positions with the truth); truth.json keeps them, and
    `aacmm-pin simulate --points` writes such a campaign."""
    sim = simulate_campaign(torso, _config(0))
    assert {k: v.tolist() for k, v in sim.truth.extensions.items()} == {
        f"lateral_compliance[A{a}]": list(k) for a, k in HIDDEN.items()}
    points = sim.campaign.points
    assert sim.campaign.spat is None and points is not None and len(points.q) == POINTS
    model = stylus_positions(torso, sim.truth, points.q, frame="mt", tool=points.tool)
    np.testing.assert_allclose(model, sim.sphere_mt, atol=1e-12)
    noise = points.point - sim.sphere_mt
    assert abs(noise.std() / SIGMA - 1) < 0.05
    ap.write_simulation(sim, tmp_path / "sim")
    truth = json.loads((tmp_path / "sim" / "truth.json").read_text())
    assert truth["extensions"]["lateral_compliance[A10]"] == [4e-5, 3e-5]
    assert (tmp_path / "sim" / "truth_points.csv").read_text().count("\n") == POINTS + 1
    assert cli.main(["simulate", str(tmp_path / "cli"), "--arm", str(TORSO), "--points", "40",
                     "--effects", "dh,lateral_compliance"]) == 0
    back = ap.read_campaign(tmp_path / "cli", arm=torso)
    assert back.points is not None and len(back.points.q) == 40
    assert "lateral_compliance[A1]" in ap.read_parameters(tmp_path / "cli" / "truth.json").extensions


# ------------------------------------------------------------------------------ discovery
class Outcome(NamedTuple):
    """One seed's discovery against the fit of the true model."""

    named: dict[str, list[int]]
    """Effect -> the axes discovery named."""
    heldout: float
    """Discovery's final 5-fold held-out RMS, m."""
    heldout_true: float
    """The same held-out RMS of the fit of the true model (DH + the hidden terms), m."""
    fresh: float
    """RMS error of discovery's calibration on 1000 fresh poses (same robot), m."""
    fresh_true: float
    """The same for the fit of the true model, m."""
    start: float
    """The DH model's held-out RMS, m."""


def _fresh_rms(arm: ap.Arm, truth: ap.Parameters, cal: ap.Parameters, seed: int) -> float:
    """RMS error of a calibration's points on fresh poses of the same robot (noise-free), m."""
    rng = np.random.default_rng(10_000 + seed)
    lim = arm.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (POINTS, arm.n_axes))
    tool = np.where(np.arange(POINTS) % 2, "right", "left")
    err = (stylus_positions(arm, cal, q, frame="mt", tool=tool)
           - stylus_positions(arm, truth, q, frame="mt", tool=tool))
    return float(np.sqrt(np.mean(err ** 2)))


def _outcome(arm: ap.Arm, seed: int, hidden: dict[int, tuple[float, float]] = HIDDEN) -> Outcome:
    sim = simulate_campaign(arm, _config(seed, hidden))
    found = discover(sim.campaign, arm, "dh", effects=["all"])
    named: dict[str, list[int]] = {}
    for step in found.steps:
        named.setdefault(step.effect, []).extend(a for t in step.terms for a in t.axes)
    true = ap.identify(sim.campaign, arm, model="dh",
                       extensions=tuple(terms_of(sim.truth.extensions)))
    assert true.success
    samples = measurements(sim.campaign, arm, True).samples
    return Outcome({k: sorted(v) for k, v in named.items()}, found.heldout_rms[-1],
                   LinearScorer(true, samples).heldout_rms,
                   _fresh_rms(arm, sim.truth, found.calibration.parameters, seed),
                   _fresh_rms(arm, sim.truth, true.parameters, seed), found.heldout_rms[0])


def _check(outcome: Outcome) -> None:
    assert outcome.heldout < 1.2 * outcome.heldout_true, outcome
    assert outcome.fresh < 1.2 * outcome.fresh_true + 1e-6, outcome  # + 1 um: both ~noise/sqrt(n)
    assert outcome.start > 3 * outcome.heldout  # the DH model misses a 0.4 mm effect


def test_discovery_names_the_hidden_lateral_compliance(torso: ap.Arm) -> None:
    """Seed 0: from dh, with every effect of the library, discovery names lateral compliance on
    exactly the hidden joints and nothing else; its held-out RMS (5-fold, and on fresh poses) is
    within 1.2x of the fit of the true model."""
    outcome = _outcome(torso, 0)
    assert outcome.named == {"lateral_compliance": sorted(HIDDEN)}, outcome
    _check(outcome)


def _five_seeds(arm: ap.Arm, hidden: dict[int, tuple[float, float]], case: str) -> list[Outcome]:
    """Discovery on seeds 0-4 (printed): exact on at least 4 of 5, held-out within 1.2x of the
    fit of the true model on every seed."""
    outcomes = [_outcome(arm, seed, hidden) for seed in range(5)]
    for seed, o in enumerate(outcomes):
        print(f"{case}, seed {seed}: named {o.named}; held-out {o.start * 1e6:.1f} -> "
              f"{o.heldout * 1e6:.2f} um (true model {o.heldout_true * 1e6:.2f}); fresh poses "
              f"{o.fresh * 1e6:.2f} um (true model {o.fresh_true * 1e6:.2f})")
    exact = [o.named == {"lateral_compliance": sorted(hidden)} for o in outcomes]
    assert sum(exact) >= 4, outcomes
    for o in outcomes:
        assert o.heldout < 1.2 * o.heldout_true, o
    return outcomes


@pytest.mark.slow
def test_discovery_names_the_hidden_lateral_compliance_on_five_seeds(torso: ap.Arm) -> None:
    """Seeds 0-4: lateral compliance named on exactly the hidden joints (and nothing else) on at
    least 4 of 5; on every seed the held-out RMS (and on fresh poses) within 1.2x of the fit of
    the true model."""
    for o in _five_seeds(torso, HIDDEN, "T1, L2, R2"):
        _check(o)


OTHER_JOINTS = {5: (3e-5, 2e-5), 9: (2e-5, 4e-5), 12: (4e-5, 3e-5)}
"""Lateral compliance hidden on other joints: the left elbow's roll (L4 = A5), the right shoulder
roll (R1 = A9) and the right elbow (R4 = A12)."""
AT_DEFAULT_SIZE = {1: (1e-5, 0.7e-5), 3: (0.7e-5, 1.3e-5), 10: (1.3e-5, 1e-5)}
"""Lateral compliance of the default plausible size (1e-5 rad/(N m)), for the torso without its
sizes file (the default sizes), 0.13 mm RMS at the markers: about the noise per coordinate."""


@pytest.mark.slow
@pytest.mark.parametrize("case", ["other joints", "default sizes"])
def test_discovery_names_lateral_compliance_elsewhere_and_at_the_default_size(
        torso: ap.Arm, case: str, tmp_path: Path) -> None:
    """The same on other joints, and at the default sizes with an effect of that size."""
    arm, hidden = torso, OTHER_JOINTS
    if case == "default sizes":  # the same robot without its sizes file
        (tmp_path / "torso.urdf").write_bytes(TORSO.read_bytes())
        arm, hidden = ap.load_arm(tmp_path / "torso.urdf"), AT_DEFAULT_SIZE
        assert arm.sizes.effects["lateral_compliance"] == 1e-5
    _five_seeds(arm, hidden, case)
