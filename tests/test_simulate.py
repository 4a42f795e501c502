"""Simulator and predict: truth reproduced exactly, same seed same files, effects switchable."""

from __future__ import annotations

import csv
import filecmp

import numpy as np
import pytest

from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import read_campaign, read_readouts
from aacmm_pin.model.arm import load_arm
from aacmm_pin.model.parameters import read_parameters
from tests.helpers import SAMPLE


def _points(path) -> np.ndarray:
    with open(path) as fh:
        return np.array([[float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])]
                         for r in csv.DictReader(fh)])


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "campaign"
    assert main(["simulate", str(out), "--seed", "3"]) == 0
    return out


def test_predict_reproduces_simulated_spheres(simulated, tmp_path):
    """predict with truth.json gives the true sphere centres of every SPAT sample (MT-CS)."""
    assert main(["predict", str(simulated / "truth.json"), str(simulated / "spat.csv"),
                 "--out", str(tmp_path / "p.csv")]) == 0
    truth = read_parameters(simulated / "truth.json")
    p_mt = (_points(tmp_path / "p.csv") / 1e3) @ truth.rotation().T + truth.translation
    # files hold mm with 9 decimals: 5e-10 mm rounding per value
    np.testing.assert_allclose(p_mt * 1e3, _points(simulated / "truth_spheres.csv"), atol=2e-9)


def test_predict_reproduces_simulated_sockets(simulated, tmp_path):
    """predict with truth.json puts every length-bar posture on its true socket (r-CS)."""
    assert main(["predict", str(simulated / "truth.json"), str(simulated / "lengthbar.csv"),
                 "--out", str(tmp_path / "p.csv")]) == 0
    pred = _points(tmp_path / "p.csv")
    with open(simulated / "truth_sockets.csv") as fh:
        sockets = {(int(r["placement"]), r["socket"]):
                   np.array([float(r[k]) for k in ("x_mm", "y_mm", "z_mm")])
                   for r in csv.DictReader(fh)}
    log = read_campaign(simulated).lengthbar
    ref = np.array([sockets[(int(p), str(s))] for p, s in zip(log.placement, log.socket)])
    # readouts are written with 9 decimals of a degree: 1.7e-11 rad x 1.5 m reach < 3e-8 mm
    np.testing.assert_allclose(pred, ref, atol=3e-8)


def test_predict_keeps_the_input_id_columns(simulated, tmp_path):
    """predict's output keeps the readouts file's own columns (placement, socket, t_s...) row by row,
    so every point can be found again; the readout columns are not repeated."""
    assert main(["predict", str(simulated / "truth.json"), str(simulated / "lengthbar.csv"),
                 "--out", str(tmp_path / "p.csv")]) == 0
    with open(tmp_path / "p.csv") as fh:
        out = list(csv.DictReader(fh))
    with open(simulated / "lengthbar.csv") as fh:
        src = list(csv.DictReader(fh))
    assert list(out[0])[:2] == ["placement", "socket"] and list(out[0])[-3:] == ["x_mm", "y_mm", "z_mm"]
    assert not [k for k in out[0] if k.startswith("q")]
    assert [(r["placement"], r["socket"]) for r in out] == [(r["placement"], r["socket"]) for r in src]


def test_campaign_has_the_requested_shape(simulated):
    """4 nests 0.45-0.72 m from A1, 200 samples each, displacement <= 15 um + 2 um noise, 7x3x40 bar."""
    camp = read_campaign(simulated)
    truth = read_parameters(simulated / "truth.json")
    assert list(camp.location_ids) == [1, 2, 3, 4] and len(camp.spat.location) == 800
    for p in camp.locations.values():
        p_r = truth.rotation().T @ (p - truth.translation)
        assert 0.45 <= np.hypot(p_r[0], p_r[1]) <= np.hypot(0.711, 0.131)
    true_disp = _points(simulated / "truth_spheres.csv") / 1e3 - np.array(
        [truth.extra["effects"]["locations_true_mm"][str(m)] for m in camp.spat.location]) / 1e3
    assert np.linalg.norm(true_disp, axis=1).max() <= 15e-6 + 1e-12
    noise = camp.spat.displacement - true_disp
    assert 1.7e-6 < noise.std() < 2.3e-6  # sigma 2 um over 2400 values
    assert len(camp.lengthbar.placement) == 7 * 3 * 40
    lim = load_arm().joint_limits
    assert np.all((camp.spat.q >= lim[:, 0] - 1e-9) & (camp.spat.q <= lim[:, 1] + 1e-9))


def test_same_seed_same_files(simulated, tmp_path):
    """Simulating twice with one seed writes identical files; another seed differs."""
    assert main(["simulate", str(tmp_path / "again"), "--seed", "3"]) == 0
    names = ["spat.csv", "locations.csv", "lengthbar.csv", "bar.csv", "truth.json"]
    match, mismatch, errors = filecmp.cmpfiles(simulated, tmp_path / "again", names, shallow=False)
    assert match == names, (mismatch, errors)
    assert main(["simulate", str(tmp_path / "other"), "--seed", "4", "--samples-per-location", "5",
                 "--samples-per-socket", "2"]) == 0
    assert not filecmp.cmp(simulated / "spat.csv", tmp_path / "other" / "spat.csv", shallow=False)


def test_effects_switch_on_and_off():
    """Compliance, thermal and backlash move the true stylus; without them it is kinematic."""
    arm = load_arm()
    small = dict(samples_per_location=5, samples_per_socket=3, bar_placements=1)
    base = simulate_campaign(arm, SimulationConfig(seed=1, **small))
    for effect in ("compliance", "thermal", "backlash"):
        sim = simulate_campaign(arm, SimulationConfig(
            seed=1, effects=("dh", "encoder", "rtest", effect), **small))
        assert effect in sim.truth.extra["effects"]["switched_on"]
        from aacmm_pin.effects.calibrated import stylus_positions
        kin = stylus_positions(arm, sim.truth, sim.campaign.spat.q, "mt")
        gap = np.abs(kin - sim.sphere_mt).max()
        assert gap > 1e-6, effect  # the effect is not in the kinematic model: it must show
    kin = stylus_positions(arm, base.truth, base.campaign.spat.q, "mt")
    np.testing.assert_allclose(kin, base.sphere_mt, atol=1e-12)
    assert (simulate_campaign(arm, SimulationConfig(
        seed=1, effects=("dh", "encoder", "thermal"), **small)).campaign.spat.temp is not None)


@pytest.mark.parametrize("effects", [("dh", "encoder", "rtest"),
                                     ("dh", "encoder", "compliance", "backlash")])
def test_inverse_kinematics_forms_no_identification_columns(monkeypatch, effects):
    """The simulator's and the planner's IK use the joint Jacobian only (issue 26): the full
    Jacobian of the identification model (DH, tool and map columns: ~40 columns formed thousands
    of times to use 7) is never asked for, and every posture still puts the true stylus on its
    target (the SPAT sphere on its nest plus the seat displacement; the bar sockets)."""
    from aacmm_pin.effects.calibrated import stylus_ik, stylus_positions
    from aacmm_pin.model._chain import BatchedChain

    def refuse(*args, **kwargs):
        raise AssertionError("inverse kinematics formed the full identification Jacobian")

    monkeypatch.setattr(BatchedChain, "jacobians", refuse)
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=2, effects=effects, samples_per_location=8,
                                                  samples_per_socket=2, bar_placements=1))
    camp, truth = sim.campaign, sim.truth
    # targets rebuilt from the truth record: nest + seat displacement (the R-Test reading less
    # its noise: within 5 sigma of 2 um) for SPATs, the socket for the bar
    nests = {int(m): np.array(p) * 1e-3 for m, p in
             truth.extra["effects"]["locations_true_mm"].items()}
    reached = sim.sphere_mt - np.array([nests[m] for m in camp.spat.location])
    assert np.abs(reached - camp.spat.displacement).max() < 5 * 2e-6
    if "compliance" not in effects:  # kinematic: the bar readouts reach their sockets
        bar = stylus_positions(arm, truth, camp.lengthbar.q)
        sockets = np.array([sim.sockets_r[k][s] for k, s in
                            zip(camp.lengthbar.placement, camp.lengthbar.socket)])
        assert np.abs(bar - sockets).max() < 1e-9  # 9-decimal degrees in the file: ~1e-11 m
    target = np.array([[0.4, 0.1, 0.2], [0.3, -0.3, 0.1]])
    q = stylus_ik(arm, truth, target, np.random.default_rng(0))
    np.testing.assert_allclose(stylus_positions(arm, truth, q), target, rtol=0, atol=1e-12)


@pytest.mark.skipif(not SAMPLE.is_dir(), reason="shared sample campaign not beside the project")
def test_predict_on_independent_sample_campaign(tmp_path):
    """With the sample's truth, predicted spheres match the R-Test within its noise, bars exactly."""
    truth = read_parameters(SAMPLE / "truth.json")
    camp = read_campaign(SAMPLE)
    from aacmm_pin.effects.calibrated import predict
    arm = load_arm(truth.arm)
    p_mt = predict(arm, truth, camp.spat.q) @ truth.rotation().T + truth.translation
    measured = np.array([camp.locations[m] for m in camp.spat.location]) + camp.spat.displacement
    for m in camp.location_ids:
        res = (p_mt - measured)[camp.spat.location == m]
        # R-Test noise sigma 2 um: the std of 200 samples is within 2 +- 0.4 um (4 sigma)
        assert np.all((res.std(axis=0) > 1.6e-6) & (res.std(axis=0) < 2.4e-6))
        # location error sigma 3 um plus the mean noise: an offset within 5 sigma
        assert np.all(np.abs(res.mean(axis=0)) < 15e-6)
    bar = camp.lengthbar
    pts = predict(arm, truth, bar.q)
    for k in np.unique(bar.placement):
        mean = {s: pts[(bar.placement == k) & (bar.socket == s)].mean(axis=0) for s in "ABC"}
        for (a, b), length in camp.bar.items():
            assert abs(np.linalg.norm(mean[b] - mean[a]) - length) < 1e-9  # 1 nm
    np.testing.assert_allclose(read_readouts(SAMPLE / "lengthbar.csv"), bar.q)


def test_compliance_option_sets_the_hidden_joints_by_axis_or_joint_name(tmp_path, capsys):
    """simulate --compliance T2=...,A15=...: the truth holds exactly those axes and values; an
    unknown axis is one line naming the arm's axes (exit 2)."""
    import json

    assert main(["simulate", "--arm", "torso_coupled", "--points", "20", "--effects",
                 "dh,compliance", "--compliance", "T2=4e-6,T4=1e-5,L2=6e-6,A15=8e-6",
                 str(tmp_path / "c")]) == 0
    truth = json.loads((tmp_path / "c" / "truth.json").read_text())
    assert truth["effects"]["compliance_rad_per_nm"] == {"2": 4e-6, "4": 1e-5, "6": 6e-6,
                                                          "15": 8e-6}
    capsys.readouterr()
    assert main(["simulate", "--arm", "torso_coupled", "--points", "20", "--compliance", "X9=1",
                 str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'X9' is no axis of torso_coupled" in err[0] and "T4" in err[0]
