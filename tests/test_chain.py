"""Batched kinematics against Pinocchio's own per-sample forward kinematics and frame Jacobian."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import aacmm_pin as ap
from aacmm_pin.effects import calibrated as kinematics
from aacmm_pin.model import kinematics as model_kinematics
from aacmm_pin.model._chain import CHUNK, BatchedChain
from aacmm_pin.model.encoder_map import EncoderMap, correct_readouts
from aacmm_pin.model.samples import Samples

ROOT = Path(__file__).resolve().parents[1]
ARMS = ["aacmm7", "ur5", "wam7", str(ROOT / "urdf" / "torso.urdf")]
# Every value is a sum of a few dozen products of O(1 m) terms: rounding ~ 40 eps ~ 1e-14 m; a
# wrong joint, axis or sign is off by O(1 mm) or more.
TOL = 1e-12


@pytest.fixture(scope="module", params=ARMS, ids=["aacmm7", "ur5", "wam7", "torso"])
def any_arm(request: pytest.FixtureRequest) -> ap.Arm:
    return ap.load_arm(request.param)


def _pinocchio(model: pin.Model, q: np.ndarray, frames: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Pinocchio, one sample at a time: frame origins (N, 3) and linear frame Jacobians (N, 3, nv)."""
    data = model.createData()
    pos, jac = np.empty((len(q), 3)), np.empty((len(q), 3, model.nv))
    for i, (qi, fid) in enumerate(zip(q, frames)):
        jac[i] = pin.computeFrameJacobian(model, data, qi, int(fid), pin.LOCAL_WORLD_ALIGNED)[:3]
        pin.forwardKinematics(model, data, qi)
        pos[i] = pin.updateFramePlacement(model, data, int(fid)).translation
    return pos, jac


def _tools(arm: ap.Arm, rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.integers(0, arm.n_tools, n)


@pytest.mark.parametrize("moving", ["axes", "all"])
def test_chain_matches_pinocchio(any_arm, moving):
    """Positions and every Jacobian column equal Pinocchio's to 1e-12 (axes or all joints moving)."""
    ident = any_arm.identification
    rng = np.random.default_rng(3)
    n = 200
    q = np.tile(rng.uniform(-1.0, 1.0, ident.model.nq), (n, 1))
    if moving == "all":
        q = rng.uniform(-4.0, 4.0, (n, ident.model.nq))
    q[:, ident.axis_idx] = rng.uniform(-4.0, 4.0, (n, any_arm.n_axes))
    frames = np.asarray(ident.tool_frames)[_tools(any_arm, rng, n)]
    ref_pos, ref_jac = _pinocchio(ident.model, q, frames)
    pos, jac = ident.chain.jacobians(q, frames)
    np.testing.assert_allclose(pos, ref_pos, rtol=0, atol=TOL)
    np.testing.assert_allclose(jac, ref_jac, rtol=0, atol=TOL)
    np.testing.assert_allclose(ident.chain.positions(q, frames), ref_pos, rtol=0, atol=TOL)
    if any_arm.n_tools > 1:  # the other tool's vector and the other arm's axes: zero columns
        other = jac[frames == ident.tool_frames[0]][:, :, ident.tool_idx[3:]]
        assert other.shape[0] > 0 and not other.any()


def test_chain_across_chunks_and_one_sample(arm):
    """More samples than a chunk (some joints fixed in one chunk only) and a single sample agree."""
    ident = arm.identification
    rng = np.random.default_rng(4)
    n = CHUNK + 37
    q = np.tile(rng.uniform(-1.0, 1.0, ident.model.nq), (n, 1))
    q[:, ident.axis_idx] = rng.uniform(-3.0, 3.0, (n, arm.n_axes))
    q[CHUNK:, ident.error_idx[0]] += rng.normal(0.0, 1e-3, 37)  # moves in the last chunk only
    q[:CHUNK, ident.axis_idx[2]] = 0.3                           # fixed in the first chunk
    frames = np.full(n, ident.stylus_frame)
    ref_pos, ref_jac = _pinocchio(ident.model, q, frames)
    pos, jac = ident.chain.jacobians(q, frames)
    np.testing.assert_allclose(jac, ref_jac, rtol=0, atol=TOL)
    np.testing.assert_allclose(pos, ref_pos, rtol=0, atol=TOL)
    one_pos, one_jac = ident.chain.jacobians(q[:1], frames[:1])
    np.testing.assert_allclose(one_jac, ref_jac[:1], rtol=0, atol=TOL)


def test_chain_unaligned_axes():
    """Joints about and along arbitrary axes (Pinocchio's Unaligned joints) agree with Pinocchio."""
    model = pin.Model()
    rng = np.random.default_rng(5)
    parent = 0
    for k in range(6):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        joint = (pin.JointModelRevoluteUnaligned(axis) if k % 2 == 0
                 else pin.JointModelPrismaticUnaligned(axis))
        placement = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
        parent = model.addJoint(parent, joint, placement, f"j{k}")
    fid = model.addFrame(pin.Frame("tip", parent, 0, pin.SE3(np.eye(3), np.array([0.1, 0.2, 0.3])),
                                   pin.FrameType.OP_FRAME))
    q = rng.uniform(-3.0, 3.0, (50, model.nq))
    frames = np.full(50, fid)
    ref_pos, ref_jac = _pinocchio(model, q, frames)
    pos, jac = BatchedChain(model).jacobians(q, frames)
    np.testing.assert_allclose(pos, ref_pos, rtol=0, atol=TOL)
    np.testing.assert_allclose(jac, ref_jac, rtol=0, atol=TOL)


def test_chain_rejects_other_joints():
    """A joint with more than one degree of freedom is refused, by name."""
    model = pin.Model()
    model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    with pytest.raises(ValueError, match="ball"):
        BatchedChain(model)


def _off_nominal(arm: ap.Arm, seed: int) -> tuple[ap.Parameters, Samples]:
    """Random DH, tools, X0, maps and extensions (compliance, thermal, crosstalk) and samples."""
    rng = np.random.default_rng(seed)
    nominal = ap.Parameters.nominal(arm)
    dh = {f.name: v + rng.normal(0.0, 1e-3) for f, v in zip(arm.error_frames, nominal.dh.values())}
    tools = {k: v + rng.normal(0.0, 1e-3, 3) for k, v in nominal.tool_vectors(arm).items()}
    maps = {a: EncoderMap(rng.normal(0.0, 1e-4, 72)) for a in range(1, arm.n_axes + 1)}
    ext = {"compliance[A2]": np.array([1e-5]), "thermal": np.array([2e-5]),
           "crosstalk[A3<-A1]": np.array([1e-4, -2e-4])}
    params = nominal.replace(dh=dh, tools=tools, encoder_maps=maps, extensions=ext,
                             rotation_abc=rng.normal(0.0, 0.1, 3),
                             translation=rng.normal(0.0, 0.5, 3))
    n = 60
    q = rng.uniform(arm.joint_limits[:, 0], arm.joint_limits[:, 1], (n, arm.n_axes))
    samples = Samples(arm, q, temp=rng.uniform(15.0, 25.0, n), t=np.arange(n, dtype=float),
                      tool=_tools(arm, rng, n))
    return params, samples


def _reference_jacobians(arm: ap.Arm, params: ap.Parameters, samples: Samples, frame: str
                         ) -> model_kinematics.StylusJacobians:
    """The public Jacobians computed sample by sample with Pinocchio's computeFrameJacobian."""
    ident = arm.identification
    q_read = samples.q
    change = kinematics.extension_adjustment(arm, params, q_read, samples)
    assert change is not None
    offsets, scale = change.offsets, change.scale
    q = model_kinematics.identification_configuration(arm, params, q_read, frame, offsets)
    pos, jac = _pinocchio(ident.model, q, np.asarray(ident.tool_frames)[samples.tool])
    origin = params.translation if frame == "mt" else np.zeros(3)
    pos = origin + scale[:, None] * (pos - origin)
    jac = jac * scale[:, None, None]
    jac[:, :, ident.base_idx[:3]] /= scale[:, None, None]
    angles = jac[:, :, ident.axis_idx]
    slope = 1.0 + np.column_stack([params.encoder_maps[a].slope(q_read[:, a - 1])
                                   for a in range(1, arm.n_axes + 1)])
    return model_kinematics.StylusJacobians(
        position=pos, readouts=angles * slope[:, None, :], angles=angles,
        dh=jac[:, :, ident.error_idx], tool=jac[:, :, ident.tool_idx],
        rotation=jac[:, :, ident.base_idx[[4, 3, 5]]], translation=jac[:, :, ident.base_idx[:3]],
        q_readout=q_read)


@pytest.mark.parametrize("frame", ["r", "mt"])
def test_public_kinematics_match_pinocchio_off_nominal(any_arm, frame):
    """stylus_jacobians and stylus_positions equal Pinocchio per sample to 1e-12, every field."""
    params, samples = _off_nominal(any_arm, 6)
    ref = _reference_jacobians(any_arm, params, samples, frame)
    got = kinematics.stylus_jacobians(any_arm, params, samples.q, frame, samples)
    for name in (f for f in ref._fields if f not in ("tilts", "frame_columns")):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=0, atol=TOL,
                                   err_msg=name)
    np.testing.assert_allclose(kinematics.stylus_positions(any_arm, params, samples.q, frame,
                                                           samples), ref.position, rtol=0, atol=TOL)


def test_predict_matches_pinocchio_runtime_model(any_arm):
    """predict equals Pinocchio's forward kinematics of the calibrated runtime model per sample."""
    params, samples = _off_nominal(any_arm, 7)
    model = any_arm.runtime_model(params.dh, tools=params.tool_vectors(any_arm))
    change = kinematics.extension_adjustment(any_arm, params, samples.q, samples)
    assert change is not None
    offsets, scale = change.offsets, change.scale
    q = correct_readouts(samples.q, params.encoder_maps) + offsets
    fids = np.array([model.getFrameId(link) for link in any_arm.tool_links])[samples.tool]
    ref = _pinocchio(model, q, fids)[0] * scale[:, None]
    np.testing.assert_allclose(kinematics.predict(any_arm, params, samples.q, samples), ref,
                               rtol=0, atol=TOL)


def _tilted_positions(model: pin.Model, joint: int, rotation: np.ndarray, q: np.ndarray,
                      frames: np.ndarray) -> np.ndarray:
    """Pinocchio's frame origins with joint ``joint``'s child side turned by ``rotation`` (its
    joint frame): every child joint's and frame's placement premultiplied by it."""
    tilted = model.copy()
    turn = pin.SE3(rotation, np.zeros(3))
    for child in range(1, tilted.njoints):
        if tilted.parents[child] == joint:
            tilted.jointPlacements[child] = turn * tilted.jointPlacements[child]
    for frame in tilted.frames:
        if frame.parentJoint == joint:
            frame.placement = turn * frame.placement
    data = tilted.createData()
    out = np.empty((len(q), 3))
    for i, (qi, fid) in enumerate(zip(q, frames)):
        pin.forwardKinematics(tilted, data, qi)
        out[i] = pin.updateFramePlacement(tilted, data, int(fid)).translation
    return out


@pytest.mark.parametrize("which", ["aacmm7", "torso"])
@pytest.mark.parametrize("model_kind", ["identification", "runtime"])
def test_tilt_columns_equal_pinocchio_central_differences(which, model_kind):
    """tilt_columns equal central differences of Pinocchio's forward kinematics with each joint's
    child side turned by exp(eps u) about its lateral axes (u: x, y of the joint's basis), to
    1e-9 relative, and are zero for the joints not supporting the frame."""
    arm = ap.load_arm(ARMS[0] if which == "aacmm7" else ARMS[3])
    rng = np.random.default_rng(11)
    n = 12
    tool_index = np.arange(n) % arm.n_tools
    if model_kind == "identification":
        ident = arm.identification
        model, chain = ident.model, ident.chain
        q = np.tile(rng.uniform(-0.01, 0.01, model.nq), (n, 1))
        q[:, ident.axis_idx] = rng.uniform(-2.0, 2.0, (n, arm.n_axes))
        frames = np.asarray(ident.tool_frames)[tool_index]
        axes = ident.axis_idx
    else:
        model = arm.runtime_model()
        chain = BatchedChain(model)
        q = rng.uniform(-2.0, 2.0, (n, model.nq))
        frames = np.array([model.getFrameId(link) for link in arm.tool_links])[tool_index]
        axes = np.array([model.joints[model.getJointId(a)].idx_q for a in arm.axis_names])
    cols = chain.tilt_columns(q, frames, axes)
    assert cols.shape == (n, 3, axes.size, 2)
    eps = 1e-6
    scale = np.abs(cols).max()
    for col, idx_q in enumerate(axes):
        joint = next(j for j in range(1, model.njoints) if model.joints[j].idx_q == idx_q)
        for k in range(2):
            u = chain.basis(joint)[:, k]
            plus = _tilted_positions(model, joint, pin.exp3(eps * u), q, frames)
            minus = _tilted_positions(model, joint, pin.exp3(-eps * u), q, frames)
            fd = (plus - minus) / (2 * eps)
            # central differences: truncation ~eps^2, rounding ~1e-16 m / eps = 1e-10 of O(1 m)
            np.testing.assert_allclose(cols[:, :, col, k], fd, rtol=0, atol=1e-9 * scale,
                                       err_msg=f"{model.names[joint]} lateral {'xy'[k]}")
    if arm.n_tools > 1:  # the other arm's joints do not move a tool
        for tool, other in (("left", "R"), ("right", "L")):
            rows = tool_index == arm.tool_names.index(tool)
            cols_other = [c for c, name in enumerate(arm.axis_names) if name.startswith(other)]
            assert rows.any() and not cols[rows][:, :, cols_other].any()


@pytest.mark.parametrize("model_kind", ["identification", "runtime"])
def test_joint_jacobians_equal_pinocchio_columns(any_arm, model_kind):
    """The joint columns alone (inverse kinematics) equal Pinocchio's frame Jacobian's, to 1e-12:
    joints moving per sample, fixed after a moving one (the DH error joints) and one sample."""
    rng = np.random.default_rng(8)
    n = 40
    if model_kind == "identification":
        ident = any_arm.identification
        model, chain, frames = ident.model, ident.chain, np.asarray(ident.tool_frames)
        joints = np.asarray(ident.axis_idx)
        q = np.tile(rng.uniform(-1.0, 1.0, model.nq), (n, 1))
    else:
        model = any_arm.runtime_model()
        chain = BatchedChain(model)
        frames = np.array([model.getFrameId(link) for link in any_arm.tool_links])
        joints = np.array([model.joints[model.getJointId(a)].idx_q for a in any_arm.axis_names])
        q = np.zeros((n, model.nq))
    q[:, joints] = rng.uniform(-4.0, 4.0, (n, joints.size))
    fids = frames[_tools(any_arm, rng, n)]
    ref_pos, ref_jac = _pinocchio(model, q, fids)
    for rows in (slice(None), slice(0, 1)):
        pos, jac = chain.joint_jacobians(q[rows], fids[rows], joints)
        np.testing.assert_allclose(pos, ref_pos[rows], rtol=0, atol=TOL)
        np.testing.assert_allclose(jac, ref_jac[rows][:, :, joints], rtol=0, atol=TOL)  # nq == nv


def test_joint_kinematics_equal_the_full_jacobians_readout_columns(any_arm):
    """JointKinematics gives stylus_jacobians' r-CS positions and readout columns (maps' slopes,
    extensions' offsets, tilts and scale included) without forming the DH, tool and map columns."""
    params, samples = _off_nominal(any_arm, 9)
    params = params.replace(extensions={**params.extensions,  # and a tilt
                                        "lateral_compliance[A2]": np.array([3e-5, 2e-5])})
    change = kinematics.extension_adjustment(any_arm, params, samples.q, samples)
    assert change is not None and change.tilted
    full = model_kinematics.stylus_jacobians(any_arm, params, samples.q, "r", samples,
                                             adjust=change)
    pos, jac = model_kinematics.JointKinematics(any_arm, params).position_jacobian(
        samples.q, samples.tool, change)
    np.testing.assert_allclose(pos, full.position, rtol=0, atol=TOL)
    np.testing.assert_allclose(jac, full.readouts, rtol=0, atol=TOL)
