"""A term that moves a frame (:class:`aacmm_pin.FrameTerm`): kinematics, columns and a plugin.

Any frame of the arm's Pinocchio model (the tool, the base, a link, a joint's or an error frame)
moves by a small twist in its own axes; everything hanging from it moves with it. Checked here:

* the twist columns of :class:`~aacmm_pin.model._chain.BatchedChain` against Pinocchio's own
  placements moved by ``exp6`` of the twist (finite differences, an independent path);
* a frame term's columns against central differences of the modelled point (r-CS and MT-CS, with
  a thermal scale beside it, on the torso's two tools: a frame of one arm does not move the other's);
* the runtime paths (``predict``, :class:`JointKinematics`, :class:`CalibratedArm` one sample and a
  batch, the IK Jacobian's positions) give the identification model's points;
* a plugin outside the package (``examples/07_stylus_plugin``): a stylus that grows with its own
  temperature (a column aacmm_pin has never heard of) is named by ``discover`` on a campaign that
  hides 8 ppm/K, identified within 10 %, lowers the fit RMS, and ``predict`` in a fresh process
  moves the stylus by k x 10 K x |tool| between 20 and 30 deg C.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import aacmm_pin as ap
from aacmm_pin.effects.base import FrameTerm, PluginOutputError
from aacmm_pin.effects.calibrated import stylus_jacobians, stylus_positions
from aacmm_pin.effects.calibrated_arm import CalibratedArm
from aacmm_pin.effects.forward import terms_adjustment
from aacmm_pin.model import kinematics
from aacmm_pin.model._chain import BatchedChain
from aacmm_pin.model.kinematics import JointKinematics
from aacmm_pin.model.samples import Samples
from tests.helpers import ENV, ROOT

PLUGIN = ROOT / "examples" / "07_stylus_plugin" / "aacmm_pin_stylustemp.py"
"""The stylus expansion plugin: a file outside the package."""
K_TRUE = 8e-6
"""The hidden stylus expansion coefficient, 1/K."""


def _basis(rows: np.ndarray, samples: Samples) -> np.ndarray:
    """A basis (N, 6, 2) that varies with the samples: the temperature and the first readout."""
    out = np.zeros((samples.n, 6, 2))
    assert samples.temp is not None
    out[:, :, 0] = (samples.temp - 20.0)[:, None] * rows[0]
    out[:, :, 1] = np.sin(samples.q[:, :1]) * rows[1]
    return out


def _term(frame: str, seed: int) -> FrameTerm:
    rows = np.random.default_rng(seed).normal(size=(2, 6)) * np.array([1e-5] * 3 + [2e-5] * 3)
    return FrameTerm(f"moves[{frame}]", "moves", ("moves.a", "moves.b"), (1.0, 1.0), "test",
                     frame=frame, basis_of=partial(_basis, rows),
                     variable_of=lambda s: ("none", np.zeros(s.n)))


def _samples(arm: ap.Arm, n: int = 12, seed: int = 0) -> Samples:
    rng = np.random.default_rng(seed)
    q = rng.uniform(arm.joint_limits[:, 0], arm.joint_limits[:, 1], (n, arm.n_axes))
    tool = rng.integers(0, arm.n_tools, n) if arm.n_tools > 1 else None
    return Samples(arm, q, temp=np.linspace(20.0, 30.0, n), tool=tool)


def _params(arm: ap.Arm, seed: int = 1) -> ap.Parameters:
    rng = np.random.default_rng(seed)
    dh = {k: v + rng.normal(0.0, 1e-4) for k, v in arm.nominal_errors.items()}
    return ap.Parameters.nominal(arm).replace(dh=dh, rotation_abc=(0.01, -0.02, 0.03),
                                              translation=np.array([-0.5, 0.1, 0.02]))


@pytest.fixture(scope="module")
def torso() -> ap.Arm:
    return ap.load_arm(str(ROOT / "urdf" / "torso.urdf"))


def test_twist_columns_move_pinocchio_placements(arm: ap.Arm) -> None:
    """d(tool point)/d(twist of frame m) equals the point moved by Pinocchio's exp6 of the twist."""
    model = arm.identification.model
    data = model.createData()
    chain = BatchedChain(model)
    rng = np.random.default_rng(5)
    q = rng.uniform(-0.6, 0.6, (4, model.nq))
    tool = model.getFrameId(arm.tool_links[0])
    names = [arm.tool_links[0], "link3", "A2", "universe", "base_link", "dz43", "L5z"]
    moved = [model.getFrameId(n) for n in names]
    cols = chain.twist_columns(q, np.full(len(q), tool), np.array(moved))
    h = 1e-7
    for i in range(len(q)):
        pin.framesForwardKinematics(model, data, q[i])
        point = data.oMf[tool].translation.copy()
        for c, fid in enumerate(moved):
            placement = data.oMf[fid].copy()
            local = placement.actInv(point)
            for k in range(6):
                twist = np.zeros(6)
                twist[k] = h
                moved_point = (placement * pin.exp6(pin.Motion(twist))).act(local)
                np.testing.assert_allclose((moved_point - point) / h, cols[i, :, c, k],
                                           atol=1e-6, err_msg=f"{names[c]} column {k}")


@pytest.mark.parametrize("frame", ["stylus", "link6", "A3", "dx43", "base_link"])
@pytest.mark.parametrize("output", ["r", "mt"])
def test_columns_are_central_differences(arm: ap.Arm, frame: str, output: str) -> None:
    """A frame term's columns, beside a thermal scale, are the central differences of the point.

    Step 1e-3 of the values' plausible size (1): the model is linear in the twist to first order,
    so the truncation error is ~h x (twist x lever) ~ 1e-8 of a column of ~1 m, the rounding
    error ~1e-16 m / 1e-3.
    """
    term = _term(frame, seed=len(frame))
    samples = _samples(arm)
    params = _params(arm).replace(extensions={"thermal": np.array([11e-6])})
    values = np.array([0.7, -1.3])

    def point(v: np.ndarray) -> np.ndarray:
        change = terms_adjustment([(ap.effects.thermal(), np.array([11e-6])), (term, v)],
                                  samples, arm.n_axes)
        return kinematics.stylus_positions(arm, params, samples.q, output, samples, adjust=change)

    change = terms_adjustment([(ap.effects.thermal(), np.array([11e-6])), (term, values)],
                              samples, arm.n_axes)
    stylus = kinematics.stylus_jacobians(arm, params, samples.q, output, samples, adjust=change)
    cols = term.columns(samples, stylus, params)
    assert cols.shape == (samples.n, 3, 2)
    assert np.abs(cols).max() > 1e-6  # the frame carries the tool: a real check
    for j in range(2):
        step = np.zeros(2)
        step[j] = 1e-3
        fd = (point(values + step) - point(values - step)) / 2e-3
        np.testing.assert_allclose(cols[:, :, j], fd, atol=1e-9 * np.abs(cols).max() + 1e-15)


def test_a_frame_of_one_arm_does_not_move_the_other_tool(torso: ap.Arm) -> None:
    """On the two-armed torso, a twist of one arm's link moves only that arm's tool points."""
    samples = _samples(torso, n=20, seed=3)
    assert samples.tool is not None and len(set(samples.tool.tolist())) == 2
    link = torso.tool_links[0]
    term = _term(link, seed=9)
    params = ap.Parameters.nominal(torso)
    stylus = stylus_jacobians(torso, params, samples.q, samples=samples, tool=samples.tool)
    cols = term.columns(samples, stylus, params)
    mine = samples.tool == 0
    assert np.abs(cols[mine]).min(axis=(1, 2)).size and np.all(np.abs(cols[mine]).max(axis=(1, 2)) > 0)
    assert np.all(cols[~mine] == 0.0)


def test_runtime_paths_apply_the_twist(arm: ap.Arm) -> None:
    """predict, JointKinematics (positions and the IK Jacobian's) and CalibratedArm agree."""
    from aacmm_pin.effects import registry

    class Moves(ap.Effect):
        name = "moves"

        def candidates(self, arm: ap.Arm, samples: Samples) -> list[ap.Term]:
            return []

        def term(self, key: str) -> ap.Term | None:
            return _term("link5", seed=2) if key == "moves[link5]" else None

    before = dict(registry.LIBRARY)
    registry.register_effect(Moves(), "tests")
    try:
        samples = _samples(arm, n=6)
        values = np.array([3.0, -2.0])
        params = _params(arm).replace(extensions={"moves[link5]": values})
        plain = _params(arm)
        moved = ap.predict(arm, params, samples.q, samples)
        still = ap.predict(arm, plain, samples.q, samples)
        assert np.abs(moved - still).max() > 1e-5  # the twist moves the points
        ident = stylus_positions(arm, params, samples.q, "r", samples)
        np.testing.assert_allclose(moved, ident, atol=1e-12)
        change = terms_adjustment([(_term("link5", seed=2), values)], samples, arm.n_axes)
        pos, _ = JointKinematics(arm, params).position_jacobian(samples.q, adjust=change)
        np.testing.assert_allclose(pos, ident, atol=1e-12)
        runtime = CalibratedArm(arm, params)
        columns = {"temp_c": samples.temp}
        assert samples.temp is not None
        np.testing.assert_allclose(runtime.position(samples.q, columns=columns), ident, atol=1e-12)
        one = runtime.position(samples.q[2], columns={"temp_c": samples.temp[2:3]})
        np.testing.assert_allclose(one, ident[2], atol=1e-12)
    finally:
        registry.LIBRARY.clear()
        registry.LIBRARY.update(before)


@pytest.mark.parametrize("frame", ["flange_x", "tool_x", "mt_x", "gamma0", "universe"])
def test_a_frame_the_urdf_lacks_is_refused_naming_the_term(arm: ap.Arm, frame: str) -> None:
    """A frame that is not the URDF's (a typo, or a joint only the identification model has): one
    line naming the term, its effect and the URDF's frames, on every path."""
    samples = _samples(arm, n=3)
    term = _term(frame, seed=1)
    with pytest.raises(PluginOutputError, match=rf"term moves\[{frame}\] \(effect 'moves'.*"
                                                rf"'{frame}' is not in the arm; choose from: .*link6"):
        terms_adjustment([(term, np.ones(2))], samples, arm.n_axes)
    stylus = stylus_jacobians(arm, _params(arm), samples.q, samples=samples)
    with pytest.raises(PluginOutputError, match=rf"moves\[{frame}\]"):
        term.columns(samples, stylus, _params(arm))


def test_a_tool_joint_moves_its_tool_alike_in_the_fit_and_at_run_time(arm: ap.Arm) -> None:
    """The tool joint's frame (the URDF's ``tool``) is its tool link's in the identification
    model, where the tool is three prismatic joints: the fit's path and the runtime's agree."""
    samples = _samples(arm, n=5)
    values = np.array([2.0, -1.0])
    change = terms_adjustment([(_term(arm.tool_joints[0], seed=4), values)], samples, arm.n_axes)
    params = _params(arm)
    fit = kinematics.stylus_positions(arm, params, samples.q, "r", samples, adjust=change)
    runtime = JointKinematics(arm, params).positions(samples.q, adjust=change)
    np.testing.assert_allclose(fit, runtime, atol=1e-12)
    plain = kinematics.stylus_positions(arm, params, samples.q, "r", samples)
    assert np.abs(fit - plain).max() > 1e-6


# ------------------------------------------------------------------ the plugin, end to end
def _flange_shift(arm: ap.Arm, truth: ap.Parameters, q: np.ndarray, temp: np.ndarray,
                  k: float) -> np.ndarray:
    """The stylus tip's move k (T - 20) R t of each sample in the r-CS, by Pinocchio, (N, 3), m.

    Written from the physics, not from the package's frame terms: the tool link's rotation by
    Pinocchio's forward kinematics of the true runtime model at the true joint angles.
    """
    model = arm.runtime_model(truth.dh, tools=truth.tool_vectors(arm))
    data = model.createData()
    fid = model.getFrameId(arm.tool_links[0])
    angles = arm.joint_angles(ap.correct_readouts(q, truth.encoder_maps))
    out = np.empty((len(q), 3))
    for i, theta in enumerate(angles):
        pin.framesForwardKinematics(model, data, theta)
        out[i] = data.oMf[fid].rotation @ arm.nominal_tool * k * (temp[i] - 20.0)
    return out


def _hide_expansion(arm: ap.Arm, sim: ap.Simulation, log: ap.SpatLog | ap.LengthBarLog,
                    temp: np.ndarray) -> np.ndarray:
    """Return readouts whose stylus, grown by K_TRUE (T - 20), sits where the log's sat.

    Newton steps on the joints (the least-norm move of the 7-axis arm) until the grown stylus is
    within 1e-12 m of the point the simulator put it at.
    """
    joints = JointKinematics(arm, sim.truth)
    target = joints.positions(log.q)
    q = np.array(log.q)
    for _ in range(6):
        pos, jac = joints.position_jacobian(q)
        miss = pos + _flange_shift(arm, sim.truth, q, temp, K_TRUE) - target
        if np.abs(miss).max() < 1e-12:
            return q
        q = q - np.einsum("nij,nj->ni", np.linalg.pinv(jac), miss)
    raise AssertionError("the grown stylus was not put back on its point")


def stylus_campaign(arm: ap.Arm, seed: int, folder: Path) -> Path:
    """Write a campaign (DH, encoder, R-Test; 4 x 150 SPATs, 2 bar placements) whose stylus warms
    from 20 to 30 deg C (column temp_probe_c) and grows by 8 ppm/K (hidden); return its folder."""
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(
        seed=seed, effects=("dh", "encoder", "rtest"), samples_per_location=150, bar_placements=2,
        samples_per_socket=10))
    campaign = sim.campaign
    assert campaign.spat is not None and campaign.lengthbar is not None
    rng = np.random.default_rng(seed)
    n_spat, n_bar = len(campaign.spat.q), len(campaign.lengthbar.q)
    n = n_spat + n_bar
    temp = 20.0 + 10.0 * (1.0 - np.exp(-np.arange(n) / (n / 3))) / (1.0 - np.exp(-3.0))
    temp += rng.normal(0.0, 0.05, n)
    logs = {"spat": (campaign.spat, temp[:n_spat]), "lengthbar": (campaign.lengthbar, temp[n_spat:])}
    parts = {}
    for name, (log, t) in logs.items():
        q = _hide_expansion(arm, sim, log, t)
        parts[name] = replace(log, q=q, columns={**log.columns, "temp_probe_c": t})
    ap.write_campaign(replace(campaign, **parts), folder)
    return folder


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "aacmm_pin", *args], capture_output=True,
                          text=True, env=ENV, timeout=600)


@pytest.mark.parametrize("seed", [0, *(pytest.param(s, marks=pytest.mark.slow) for s in (1, 2, 3))])
def test_a_plugin_adds_a_growing_stylus(arm: ap.Arm, seed: int, tmp_path: Path) -> None:
    """Discover names the stylus expansion, identifies 8 ppm/K within 10 %, the fit RMS falls,
    and predict in a fresh process moves the stylus by k x 10 K x |tool| from 20 to 30 deg C.

    (Seeds 0-5 gave 7.44-8.37 ppm/K; a campaign of 4 x 60 SPATs gave 7.2-9.5: too few for 10 %.)
    """
    campaign = stylus_campaign(arm, seed, tmp_path / "campaign")
    out = tmp_path / "discovery"
    done = _cli("discover", str(campaign), "--effects-file", str(PLUGIN), "--out", str(out))
    assert done.returncode == 0, done.stderr
    report = json.loads((out / "discovery.json").read_text())
    effects = [step["effect"] for step in report["steps"]]
    assert "stylus_thermal" in effects, (effects, done.stdout)
    params = json.loads((out / "parameters.json").read_text())
    k = params["extensions"]["stylus_thermal[stylus]"][0]
    assert abs(k - K_TRUE) < 0.1 * K_TRUE, k
    step = report["steps"][effects.index("stylus_thermal")]
    assert step["fit_rms_after_um"] < step["fit_rms_before_um"], step
    assert str(PLUGIN.resolve()) in json.dumps(params.get("plugins", {}))
    readouts = tmp_path / "readouts.csv"
    q_deg = np.degrees(arm.joint_limits.mean(axis=1) + 0.2)
    header = ",".join(f"q{i + 1}_deg" for i in range(arm.n_axes)) + ",temp_probe_c"
    rows = [",".join(f"{v:.9f}" for v in q_deg) + f",{t:.1f}" for t in (20.0, 30.0)]
    readouts.write_text(header + "\n" + "\n".join(rows) + "\n")
    points = tmp_path / "points.csv"
    done = _cli("predict", str(out), str(readouts), "--out", str(points), "--effects-file",
                str(PLUGIN))
    assert done.returncode == 0, done.stderr
    xyz = np.loadtxt(points, delimiter=",", skiprows=1)[:, -3:] * 1e-3  # mm -> m
    moved = np.linalg.norm(xyz[1] - xyz[0])
    # the calibration's arm (its calibrated.urdf) holds the calibrated tool; 9 decimals of mm
    np.testing.assert_allclose(moved, k * 10.0 * np.linalg.norm(params["tool"]), rtol=1e-6)


DRIFT = '''
import numpy as np
import aacmm_pin as ap


def _basis(samples):
    out = np.zeros((samples.n, 6, 1))
    out[:, 0, 0] = np.sin(samples.q[:, 0])
    return out


class Drift(ap.Effect):
    name = "drift"

    def candidates(self, arm, samples):
        return [self.term("drift[dx43]")]

    def term(self, key):
        if key != "drift[dx43]":
            return None
        return ap.FrameTerm(key, "drift", ("drift[dx43].m",), (1e-5,), "error frame dx43 slides",
                            frame="dx43", basis_of=_basis,
                            variable_of=lambda s: ("A1 (rad)", s.q[:, 0]))


ap.register_effect(Drift)
'''


def test_a_term_on_an_error_frame_survives_the_compact_urdf(arm: ap.Arm, small_sim: ap.Simulation,
                                                             tmp_path: Path) -> None:
    """The compact URDF folds the error frames: a calibration whose frame term moves one is
    evaluated on parameters.json's arm by load_calibrated, the same points as predict."""
    from aacmm_pin.effects.calibrated_folder import load_calibrated
    from aacmm_pin.effects.parameters_file import read_parameters
    from aacmm_pin.effects.registry import load_effect_file

    effects = tmp_path / "drift.py"
    effects.write_text(DRIFT)
    ap.write_campaign(small_sim.campaign, tmp_path / "campaign")
    done = _cli("identify", str(tmp_path / "campaign"), "--effects-file", str(effects), "--terms",
                "drift[dx43]", "--out", str(tmp_path / "cal"))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "cal" / "compact.json").is_file()
    load_effect_file(effects)
    from aacmm_pin.effects import registry
    try:
        params = read_parameters(tmp_path / "cal" / "parameters.json")
        assert params.extensions["drift[dx43]"][0] != 0.0
        runtime = load_calibrated(tmp_path / "cal")
        q = np.radians([[10.0, 20, 30, 40, 50, 60, 70], [-30.0, 10, 60, -20, 40, -50, 5]])
        expected = ap.predict(ap.load_arm(params.arm), params, q)
        np.testing.assert_allclose(runtime.position(q), expected, atol=1e-12)
    finally:
        registry.LIBRARY.pop("drift", None)


def test_an_effects_file_run_again_is_checked_again(arm: ap.Arm, tmp_path: Path) -> None:
    """The run-time check knows a term by its registered effect too: an effects file changed and
    run again (its frame term now without a forward change) is refused, not passed as checked."""
    from aacmm_pin.effects import registry
    from aacmm_pin.effects.contract import ContractBroken, check_once

    effects = tmp_path / "drift.py"
    effects.write_text(DRIFT)
    samples = _samples(arm, n=8)
    params = _params(arm)
    try:
        registry.load_effect_file(effects)
        check_once([registry.term_from_key("drift[dx43]")], samples, params)
        effects.write_text(DRIFT.replace("ap.FrameTerm(key", "Ghost(key").replace(
            "class Drift", "class Ghost(ap.FrameTerm):\n    def adjust(self, values, samples, out):\n"
            "        pass\n\n\nclass Drift"))
        registry.load_effect_file(effects)
        with pytest.raises(ContractBroken, match=r"drift\[dx43\].*'drift'"):
            check_once([registry.term_from_key("drift[dx43]")], samples, params)
    finally:
        registry.LIBRARY.pop("drift", None)
