"""The runtime object of a calibrated arm: predict's points on one sample and on batches, the
inverse of the maps and extension terms, placements and Jacobians, and one-line refusals."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

import aacmm_pin as ap
from aacmm_pin import effects as fx
from aacmm_pin.effects.calibrated_arm import CalibratedArm
from aacmm_pin.errors import ArgumentError
from aacmm_pin.model.encoder_map import EncoderMap, correct_readouts
from aacmm_pin.units import ARCSEC
from tests.helpers import SAMPLE, central_differences

TERMS = (fx.compliance(2), fx.thermal(), fx.backlash(3), fx.crosstalk(2, 3),
         fx.encoder_harmonic(5), fx.lateral_compliance(3))


@pytest.fixture(scope="module")
def truth(arm: ap.Arm) -> ap.Parameters:
    """The shared sample campaign's truth (written by independent code): DH errors, maps on A1-A7."""
    return ap.read_parameters(SAMPLE / "truth.json")


@pytest.fixture(scope="module")
def extended(truth: ap.Parameters) -> ap.Parameters:
    """The truth with a term of most kinds of the effect library (at plausible sizes)."""
    rng = np.random.default_rng(4)
    return truth.replace(extensions={t.key: rng.normal(0.0, 1.0, len(t.names)) * np.array(t.plausible)
                                     for t in TERMS})


def _readouts(arm: ap.Arm, n: int, seed: int) -> np.ndarray:
    lim = arm.joint_limits
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))


def test_one_sample_and_batches_are_predict(arm: ap.Arm, truth: ap.Parameters) -> None:
    """Positions on one sample (the plain-float path) and on a batch equal ap.predict to 1e-12 m;
    in the instrument's frame they are the MT-CS transform of them (paper Eq. 4)."""
    rt = CalibratedArm(arm, truth)
    q = _readouts(arm, 50, 0)
    ref = ap.predict(arm, truth, q)
    np.testing.assert_allclose(rt.position(q), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array([rt.position(qi) for qi in q]), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array([rt.position(list(qi)) for qi in q]), ref, rtol=0, atol=1e-12)
    mt = ap.stylus_positions(arm, truth, q, frame="mt")
    np.testing.assert_allclose(rt.position(q, frame="mt"), mt, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rt.position(q[3], frame="mt"), mt[3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("tilted", [True, False])
def test_extension_terms_are_predict(arm: ap.Arm, extended: ap.Parameters, tilted: bool) -> None:
    """With compliance, thermal, backlash, crosstalk, encoder harmonics and lateral compliance
    (``tilted``; without it one sample takes the plain-float path), positions equal ap.predict
    given the same temperature and motion history (a batch's row order; one sample with its
    direction stated)."""
    if not tilted:
        extended = extended.replace(extensions={k: v for k, v in extended.extensions.items()
                                                if not k.startswith("lateral")})
    rt = CalibratedArm(arm, extended)
    q = _readouts(arm, 30, 1)
    temp = np.linspace(18.0, 26.0, len(q))
    samples = ap.model.samples.Samples(arm, q, temp=temp)
    ref = ap.predict(arm, extended, q, samples)
    got = rt.position(q, columns={"temp_c": temp})
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rt.placement(q, columns={"temp_c": temp})[:, :3, 3], ref, rtol=0,
                               atol=1e-12)  # the placement's point is predict's too
    one = np.array([rt.position(q[i], columns={"temp_c": temp[i]}, direction=samples.direction[i])
                    for i in range(len(q))])
    np.testing.assert_allclose(one, ref, rtol=0, atol=1e-12)
    with pytest.raises(ap.AacmmError, match="temp_c"):
        rt.position(q)  # the thermal term needs the temperature: one line naming the column


def test_inverse_maps_round_trip_over_every_axis(arm: ap.Arm, truth: ap.Parameters) -> None:
    """readout -> true -> readout below 1e-9 rad over the whole range of every axis with a map
    (the truth's maps, and maps of 10x the plausible size with steps of 1, 5 and 10 deg)."""
    rng = np.random.default_rng(2)
    cases = [truth] + [truth.replace(encoder_maps={
        a: EncoderMap(rng.normal(0.0, 10 * 20 * ARCSEC, int(360 / step)), step)
        for a in range(1, arm.n_axes + 1)}, step_deg=step) for step in (1.0, 5.0, 10.0)]
    for params in cases:
        rt = CalibratedArm(arm, params)
        for axis in params.encoder_maps:
            lo, hi = arm.joint_limits[axis - 1]
            q = np.zeros((20001, arm.n_axes))
            q[:, axis - 1] = np.linspace(lo, hi, len(q))
            back = rt.readouts(rt.true_angles(q))
            assert np.abs(back - q).max() < 1e-9, axis
            # and the other way round: true -> readout -> true
            theta = rt.true_angles(q)
            assert np.abs(rt.true_angles(rt.readouts(theta)) - theta).max() < 1e-9, axis
            # one sample at a time (the plain-float path) gives the batch's values
            for i in range(0, len(q), 997):
                assert np.abs(rt.readouts(theta[i]) - back[i]).max() < 1e-15
                assert np.abs(rt.true_angles(q[i]) - theta[i]).max() < 1e-15


def test_inverse_with_extension_terms(arm: ap.Arm, extended: ap.Parameters) -> None:
    """The readouts of true angles give those angles back (the fixed point of the extension
    terms' angle errors, to 1e-12 rad) on batches and on one sample."""
    rt = CalibratedArm(arm, extended)
    q = _readouts(arm, 40, 3)
    cols = {"temp_c": np.full(len(q), 23.0)}
    theta = rt.true_angles(q, columns=cols)
    back = rt.readouts(theta, columns=cols)
    np.testing.assert_allclose(back, q, rtol=0, atol=1e-12)
    direction = np.ones(arm.n_axes)
    one = rt.readouts(theta[5], columns={"temp_c": 23.0}, direction=direction)
    np.testing.assert_allclose(rt.true_angles(one, columns={"temp_c": 23.0}, direction=direction),
                               theta[5], rtol=0, atol=1e-12)


def test_true_angles_are_corrected_readouts(arm: ap.Arm, truth: ap.Parameters) -> None:
    """Without extension terms the true angles are the maps' corrected readouts, on one sample and
    on batches, and the model's tool frame at them is the predicted point."""
    rt = CalibratedArm(arm, truth)
    q = _readouts(arm, 10, 4)
    theta = rt.true_angles(q)
    np.testing.assert_allclose(theta, correct_readouts(q, truth.encoder_maps), rtol=0, atol=1e-15)
    np.testing.assert_allclose(rt.true_angles(q[2]), theta[2], rtol=0, atol=1e-15)
    model, data = rt.model, rt.model.createData()
    for qi, ti in zip(q, theta):
        pin.framesForwardKinematics(model, data, ti)
        np.testing.assert_allclose(data.oMf[rt.tool_frames[0]].translation, rt.position(qi),
                                   rtol=0, atol=1e-15)


def test_placement_is_the_tool_frame(arm: ap.Arm, truth: ap.Parameters) -> None:
    """Placements: translation = position, rotation orthonormal, in MT-CS the transform of r-CS's."""
    rt = CalibratedArm(arm, truth)
    q = _readouts(arm, 8, 5)
    m = rt.placement(q)
    assert m.shape == (8, 4, 4)
    np.testing.assert_allclose(m[:, :3, 3], rt.position(q), rtol=0, atol=1e-15)
    np.testing.assert_allclose(m[:, :3, :3] @ m[:, :3, :3].transpose(0, 2, 1),
                               np.broadcast_to(np.eye(3), (8, 3, 3)), atol=1e-12)
    x0 = np.eye(4)
    x0[:3, :3], x0[:3, 3] = truth.rotation(), truth.translation
    np.testing.assert_allclose(rt.placement(q, frame="mt"), x0 @ m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rt.placement(q[1]), m[1], rtol=0, atol=1e-15)


@pytest.mark.parametrize("frame", ["r", "mt"])
def test_jacobian_against_finite_differences(arm: ap.Arm, truth: ap.Parameters, frame: str) -> None:
    """d(point)/d(readouts) (maps' slopes included) and the angular rows against central
    differences of placements: h = 1e-7 rad inside one map segment (5 deg), truncation ~h^2,
    rounding ~1e-16/h ~ 1e-9 per unit."""
    rt = CalibratedArm(arm, truth)
    q = _readouts(arm, 4, 6)
    jac = rt.jacobian(q, frame=frame)
    assert jac.shape == (4, 6, arm.n_axes)
    h = 1e-7
    for i, qi in enumerate(q):
        lin = central_differences(lambda x: rt.position(x, frame=frame), qi, np.full(arm.n_axes, h))
        np.testing.assert_allclose(jac[i, :3], lin, rtol=0, atol=1e-7)
        rot0 = rt.placement(qi, frame=frame)[:3, :3]
        ang = np.empty((3, arm.n_axes))
        for j in range(arm.n_axes):
            e = np.zeros(arm.n_axes)
            e[j] = h
            plus, minus = (rt.placement(qi + s * e, frame=frame)[:3, :3] for s in (1, -1))
            ang[:, j] = (pin.log3(plus @ rot0.T) - pin.log3(minus @ rot0.T)) / (2 * h)
        np.testing.assert_allclose(jac[i, 3:], ang, rtol=0, atol=1e-7)
    np.testing.assert_allclose(rt.jacobian(q[0], frame=frame), jac[0], rtol=0, atol=1e-15)


BAD = [
    (np.zeros((3, 6)), r"need shape \(7,\) or \(N, 7\).*got shape \(3, 6\)"),
    (np.zeros((3, 8)), r"got shape \(3, 8\)"),
    (np.zeros(6), r"got shape \(6,\)"),
    (np.zeros((2, 2, 7)), r"got shape \(2, 2, 7\)"),
    (np.array([0.1, 0.2, math.nan, 0.0, 0.0, 0.0, 0.0]), r"axis 3 \(A3\) is nan"),
    (np.array([10.0, 20.0, -30.0, 40.0, 50.0, -60.0, 70.0]), "look like degrees"),
    ("readouts", "need numbers"),
]


@pytest.mark.parametrize("method", ["true_angles", "readouts", "position", "placement", "jacobian",
                                    "configuration", "motion_direction"])
@pytest.mark.parametrize("value, message", BAD)
def test_every_method_refuses_bad_values_in_one_line(arm: ap.Arm, truth: ap.Parameters,
                                                     method: str, value: object, message: str
                                                     ) -> None:
    """A wrong axis count, NaN and degrees given for radians raise ArgumentError (a ValueError
    too), one line naming the argument, from every public method."""
    rt = CalibratedArm(arm, truth)
    call = getattr(rt, method)
    with pytest.raises(ArgumentError, match=message) as info:
        call(np.zeros(7), value) if method == "motion_direction" else call(value)
    text = str(info.value)
    assert "\n" not in text
    assert text.startswith("angles:" if method == "readouts" else "readouts:")
    assert isinstance(info.value, ValueError)
    if method == "motion_direction":  # and the other argument
        with pytest.raises(ArgumentError, match=message) as info:
            call(value, np.zeros(7))
        assert str(info.value).startswith("previous:")


def test_bad_frame_and_tool_are_refused(arm: ap.Arm, truth: ap.Parameters) -> None:
    """frame= and tool= are checked with one line naming them."""
    rt = CalibratedArm(arm, truth)
    with pytest.raises(ArgumentError, match="frame: 'r'"):
        rt.position(np.zeros(7), frame="world")
    with pytest.raises(ArgumentError, match="tool: unknown tool 'left'"):
        rt.position(np.zeros(7), tool="left")


def test_load_calibrated_reads_a_folder(arm: ap.Arm, small_cal: ap.Calibration, tmp_path) -> None:
    """A written calibration folder loads for run time and predicts what the folder's parameters
    predict through ap.predict."""
    ap.write_calibration(small_cal, arm, tmp_path / "cal")
    rt = ap.load_calibrated(tmp_path / "cal")
    folder = ap.read_calibration(tmp_path / "cal")
    q = _readouts(arm, 20, 7)
    ref = ap.predict(ap.load_arm(folder.parameters.arm), folder.parameters, q)
    np.testing.assert_allclose(rt.position(q), ref, rtol=0, atol=1e-12)
    copy = rt.copy()
    assert copy.data is not rt.data and copy.model is rt.model
    np.testing.assert_allclose(copy.position(q[0]), ref[0], rtol=0, atol=1e-12)


def test_a_map_that_folds_back_has_no_inverse() -> None:
    """A table whose corrected angle falls on a segment (error slope below -1) is refused."""
    values = np.zeros(72)
    values[10] = math.radians(6.0)  # more than the 5 deg step: the next segment falls
    emap = EncoderMap(values)
    assert not emap.invertible
    with pytest.raises(ValueError, match="no inverse"):
        emap.inverse(np.zeros(3))
    assert EncoderMap(np.full(72, 1e-3)).invertible


def test_frames_configuration_and_directions(arm: ap.Arm, truth: ap.Parameters) -> None:
    """to_arm_frame inverts frame='mt'; configuration is the model's (true angles); tool_links
    name the model's frames; motion_direction keeps an axis' side while it rests."""
    rt = CalibratedArm(arm, truth)
    q = _readouts(arm, 6, 9)
    np.testing.assert_allclose(rt.to_arm_frame(rt.position(q, frame="mt")), rt.position(q),
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(rt.to_arm_frame(rt.position(q[0], frame="mt")), rt.position(q[0]),
                               rtol=0, atol=1e-14)
    np.testing.assert_array_equal(rt.configuration(q), rt.true_angles(q))
    assert rt.configuration(q[0]).shape == (rt.model.nq,)
    assert rt.tool_links == ["stylus"] and rt.model.existFrame("stylus")
    for bad in (np.zeros((2, 2)), np.array([0.0, np.nan, 1.0]), np.zeros((2, 2, 3))):
        with pytest.raises(ArgumentError, match=r"points: need finite numbers, shape \(3,\)"):
            rt.to_arm_frame(bad)
    now = np.array([0.1, 0.0, -0.2, 0.0, 0.0, 0.0, 0.3])
    d = rt.motion_direction(np.zeros(7), now, np.array([0, -1, 1, 0, 1, 0, 0]))
    np.testing.assert_array_equal(d, [1, -1, -1, 0, 1, 0, 1])
    np.testing.assert_array_equal(rt.motion_direction(now, now), np.zeros(7))
    with pytest.raises(ArgumentError, match="direction: need"):
        rt.motion_direction(now, now, np.full(7, 2.0))


def test_pickles_and_refuses_what_it_cannot_do_in_one_line(arm: ap.Arm, truth: ap.Parameters,
                                                           extended: ap.Parameters) -> None:
    """A runtime object pickles (for worker processes); backlash on one sample without its
    direction, and a map without an inverse, are refused in one line naming the argument."""
    import pickle

    rt = CalibratedArm(arm, truth)
    q = _readouts(arm, 5, 10)
    other = pickle.loads(pickle.dumps(rt))
    np.testing.assert_array_equal(other.position(q), rt.position(q))
    ext = CalibratedArm(arm, extended)
    cols = {"temp_c": 21.0}
    with pytest.raises(ArgumentError, match=r"^direction: a term of this calibration \(.*backlash"):
        ext.position(q[0], columns=cols)
    assert ext.position(q[0], columns=cols, direction=np.zeros(arm.n_axes)).shape == (3,)
    folded = truth.map(3).values.copy()
    folded[10] += math.radians(6.0)  # the next segment falls: no inverse
    bad = CalibratedArm(arm, truth.replace(encoder_maps={**truth.encoder_maps, 3: EncoderMap(folded)}))
    assert bad.position(q[0]).shape == (3,)  # forward is fine
    with pytest.raises(ArgumentError, match=r"^maps: the map of A3 has no inverse"):
        bad.readouts(np.zeros(arm.n_axes))


def test_readouts_of_true_angles_at_the_accepted_edge(arm: ap.Arm, truth: ap.Parameters) -> None:
    """Readouts at the very bounds accepted (half a turn past a limit) give true angles whose
    readouts come back (the angles may pass the bound by the maps' size)."""
    rt = CalibratedArm(arm, truth)
    lo, hi = rt._bounds["readouts"]
    q = np.vstack([lo, hi, lo + 1e-9, hi - 1e-9])
    np.testing.assert_allclose(rt.readouts(rt.true_angles(q)), q, rtol=0, atol=1e-12)
    for row in q:
        np.testing.assert_allclose(rt.readouts(rt.true_angles(row)), row, rtol=0, atol=1e-12)


def test_an_axis_without_limits_takes_turns_and_refuses_degrees(tmp_path) -> None:
    """A continuous joint (no limits stated) takes readouts over two turns either way; beyond, the
    message says no limits are stated (not the +-pi a model uses)."""
    from tests.helpers import ROOT

    text = (ROOT / "urdf" / "ur5.urdf").read_text()
    import re as _re

    text = _re.sub(r'(<joint name="A6" type=")revolute(")', r"\1continuous\2", text)
    (tmp_path / "ur5c.urdf").write_text(text)
    arm = ap.load_arm(tmp_path / "ur5c.urdf")
    rt = CalibratedArm(arm, ap.Parameters.nominal(arm))
    q = np.array([0.1, -0.5, 0.5, 0.0, 0.3, 7.0])  # A6 past one turn
    np.testing.assert_allclose(rt.position(q), ap.predict(arm, ap.Parameters.nominal(arm), q[None])[0],
                               rtol=0, atol=1e-12)
    with pytest.raises(ArgumentError, match=r"axis 6 \(A6\) is 90 rad, more than 2 turns from zero "
                                            r"\(the URDF states no limits\)"):
        rt.position(np.array([0.1, -0.5, 0.5, 0.0, 0.3, 90.0]))


def test_another_arm_takes_the_folders_dh_values(arm: ap.Arm, small_cal: ap.Calibration,
                                                 tmp_path) -> None:
    """load_calibrated(folder, arm=...) reads parameters.json (the arm's error frames take its DH
    values); compact.json with another arm is refused in one line (its geometry is its URDF's)."""
    ap.write_calibration(small_cal, arm, tmp_path / "cal")
    q = _readouts(arm, 10, 11)
    ref = ap.load_calibrated(tmp_path / "cal").position(q)
    np.testing.assert_allclose(ap.load_calibrated(tmp_path / "cal", arm="aacmm7").position(q), ref,
                               rtol=0, atol=1e-12)
    with pytest.raises(ArgumentError, match=r"^arm: .*compact.json holds no DH values"):
        ap.load_calibrated(tmp_path / "cal" / "compact.json", arm="aacmm7")
