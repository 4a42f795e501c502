"""The effect library: term Jacobians against finite differences, kinematics with extensions,
parameters.json round trip and clear errors."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin import effects as fx
from aacmm_pin.effects import registry as _registry  # noqa: F401  (fx.registry)
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.fit.unknowns import Unknowns
from aacmm_pin.model.samples import Samples, motion_direction

ROOT = Path(__file__).resolve().parents[1]
TERMS = (fx.compliance(2), fx.compliance(4), fx.thermal(), fx.backlash(3), fx.crosstalk(2, 3),
         fx.encoder_harmonic(5), fx.rtest(), fx.lateral_compliance(3))


@pytest.fixture(scope="module")
def sim(effects_sim: ap.Simulation) -> ap.Simulation:
    """The shared small campaign with compliance and temperatures (tests/conftest.py)."""
    return effects_sim


def _with_extensions(params: ap.Parameters, rng: np.random.Generator) -> ap.Parameters:
    ext = {t.key: rng.normal(0.0, 1.0, len(t.names)) * np.array(t.plausible) for t in TERMS}
    return params.replace(extensions=ext)


@pytest.mark.parametrize("tilted", [False, True])
def test_term_columns_equal_central_differences(arm: ap.Arm, sim: ap.Simulation, tilted: bool
                                                ) -> None:
    """Every term's columns equal central differences of the modelled points. With a lateral tilt
    in the model (``tilted``) only the tilt term's columns are checked: they are exact (the tilt
    moves the point linearly in its values), while the other columns leave out the tilt's own
    change with the angles, O(tilt) ~ 1e-4 relative (a Gauss-Newton approximation)."""
    params = _with_extensions(sim.truth, np.random.default_rng(0))
    if not tilted:
        params = params.replace(extensions={**params.extensions, "lateral_compliance[A3]":
                                            np.zeros(2)})
    samples = Samples.of_spat(arm, sim.campaign.spat)
    q = samples.q
    u = Unknowns.full(arm, params, (), TERMS, samples)
    x = u.vector(params)
    _, jac = u.jacobian(x, q)
    n_terms = u.n_terms
    analytic = jac.dense[:, u.n_dense - n_terms:u.n_dense]
    plausible = np.concatenate([t.plausible for t in TERMS])
    for j in range(n_terms):
        if tilted and not u.full_names[u.n_dense - n_terms + j].startswith("lateral"):
            continue
        h = 1e-4 * plausible[j]
        e = np.zeros_like(x)
        e[u.n_dense - n_terms + j] = h
        fd = ((u.positions(x + e, q) - u.positions(x - e, q)) / (2 * h)).reshape(-1)
        # central differences: truncation ~h^2 (negligible), rounding ~1e-16 m / h of a 1 m arm
        scale = max(np.abs(analytic[:, j]).max(), 1e-300)
        np.testing.assert_allclose(analytic[:, j], fd, atol=1e-6 * scale + 1e-16 / h,
                                   err_msg=u.full_names[u.n_dense - n_terms + j])


def test_runtime_and_identification_models_agree_with_extensions(arm: ap.Arm,
                                                                  sim: ap.Simulation) -> None:
    params = _with_extensions(sim.truth, np.random.default_rng(1))
    samples = Samples.of_spat(arm, sim.campaign.spat)
    runtime = ap.predict(arm, params, samples.q, samples)
    ident = stylus_positions(arm, params, samples.q, frame="r", samples=samples)
    np.testing.assert_allclose(runtime, ident, atol=1e-12)
    plain = stylus_positions(arm, params.replace(extensions={}), samples.q, frame="r")
    assert np.abs(ident - plain).max() > 1e-6


def test_compliance_and_thermal_terms_reproduce_the_simulated_arm(arm: ap.Arm,
                                                                  sim: ap.Simulation) -> None:
    """The simulator's gravity torque comes from the true arm, the term's from the nominal URDF:
    the DH errors (~0.1 mm, 0.02 deg) change the torque by well under 1 %, i.e. < 0.1 um here."""
    truth = sim.truth.extra["effects"]
    ext = {f"compliance[A{a}]": [k] for a, k in truth["compliance_rad_per_nm"].items()}
    ext["thermal"] = [truth["thermal_alpha_per_k"]]
    params = sim.truth.replace(extensions=ext)
    samples = Samples.of_spat(arm, sim.campaign.spat)
    model = stylus_positions(arm, params, samples.q, frame="mt", samples=samples)
    assert np.abs(model - sim.sphere_mt).max() < 1e-7
    bare = stylus_positions(arm, sim.truth, samples.q, frame="mt")
    assert np.abs(bare - sim.sphere_mt).max() > 1e-5


def test_extensions_round_trip_through_parameters_json(arm: ap.Arm, sim: ap.Simulation,
                                                       tmp_path) -> None:
    params = _with_extensions(sim.truth, np.random.default_rng(2))
    ap.write_parameters(params, tmp_path / "p.json")
    back = ap.read_parameters(tmp_path / "p.json")
    assert set(back.extensions) == {t.key for t in TERMS}
    for key, values in params.extensions.items():
        np.testing.assert_array_equal(back.extensions[key], values)


@pytest.mark.parametrize("ext, match", [
    ({"gravity[A2]": [1.0]}, r"extensions\.gravity\[A2\].*not a term"),
    ({"compliance[A2]": [1.0, 2.0]}, r"extensions\.compliance\[A2\].*needs 1"),
    ({"thermal": ["hot"]}, r"extensions\.thermal.*finite numbers"),
])
def test_bad_extensions_are_named(sim: ap.Simulation, tmp_path, ext: dict, match: str) -> None:
    data = sim.truth.to_dict()
    data["extensions"] = ext
    (tmp_path / "p.json").write_text(json.dumps(data))
    with pytest.raises(ap.FileFormatError, match=match):
        ap.read_parameters(tmp_path / "p.json")


def test_extension_on_a_missing_axis_is_named(arm: ap.Arm, sim: ap.Simulation) -> None:
    with pytest.raises(ap.FileFormatError, match=r"extensions\.compliance\[A9\]"):
        fx.check_extensions(sim.truth.replace(arm=arm.name, extensions={"compliance[A9]": [1e-6]}),
                            arm)


def test_thermal_term_needs_a_temperature(arm: ap.Arm, sim: ap.Simulation) -> None:
    params = sim.truth.replace(extensions={"thermal": [1e-5]})
    with pytest.raises(ap.AacmmError, match="temp_c"):
        ap.predict(arm, params, sim.campaign.spat.q)


def test_positive_compliance_makes_the_arm_sag(arm: ap.Arm) -> None:
    """Gravity pulls the arm down: a compliant joint (k > 0) gives way and the centre of mass of
    the arm drops (Pinocchio's centre of mass: independent of the torque's sign convention)."""
    import pinocchio as pin

    model = arm.runtime_model()
    data = model.createData()
    rng = np.random.default_rng(5)
    for q in rng.uniform(-1.5, 1.5, (5, arm.n_axes)):
        samples = Samples(arm, q[None, :])
        for axis in (2, 3, 4):
            if abs(samples.gravity[0, axis - 1]) < 0.5:  # N m: hardly loaded in this posture
                continue
            ext = {f"compliance[A{axis}]": np.array([1e-4])}
            params = ap.Parameters.nominal(arm).replace(extensions=ext)
            offsets = fx.forward.adjustment(params, samples, arm.n_axes).offsets
            z_before = pin.centerOfMass(model, data, q)[2]
            z_after = pin.centerOfMass(model, data, q + offsets[0])[2]
            assert z_after < z_before


def test_backlash_side_is_kept_while_the_axis_rests(arm: ap.Arm) -> None:
    q = np.zeros((6, 1)) + np.array([[0.0], [0.1], [0.1], [0.1], [0.05], [0.05]])
    np.testing.assert_array_equal(motion_direction(q)[:, 0], [0, 1, 1, 1, -1, -1])


def test_direction_follows_time_stamps_not_row_order(arm: ap.Arm) -> None:
    rng = np.random.default_rng(0)
    q = rng.uniform(-1, 1, (30, arm.n_axes))
    t = np.arange(30.0)
    perm = rng.permutation(30)
    ordered = Samples(arm, q, t=t).direction
    shuffled = Samples(arm, q[perm], t=t[perm]).direction
    np.testing.assert_array_equal(shuffled, ordered[perm])
    np.testing.assert_array_equal(ordered[1:], np.sign(np.diff(q, axis=0)))  # never at rest


class _Mine(fx.Effect):
    name = "mine"

    def candidates(self, arm: ap.Arm, samples: Samples) -> list[fx.Term]:
        return [_mine()]

    def term(self, key: str) -> fx.Term | None:
        return _mine() if key == "mine[A3]" else None


def _mine() -> fx.Term:
    from functools import partial

    from aacmm_pin.effects.builtin.compliance import _gravity, _gravity_variable

    return fx.AngleTerm("mine[A3]", "mine", ("mine[A3].c",), (1e-5,), "a user's term", axes=(3,),
                        basis_of=partial(_gravity, 3), variable_of=partial(_gravity_variable, 3))


def test_registered_user_term_runs_and_harmonic_order_round_trips(arm: ap.Arm) -> None:
    q = np.zeros((2, arm.n_axes)) + 0.4
    params = ap.Parameters.nominal(arm).replace(extensions={"mine[A3]": [1e-4]})
    with pytest.raises(fx.EffectNotFound, match="mine"):
        ap.predict(arm, params, q)
    fx.register_effect(_Mine)
    try:
        assert np.abs(ap.predict(arm, params, q) - ap.predict(arm, ap.Parameters.nominal(arm), q)
                      ).max() > 1e-7
    finally:
        del fx.LIBRARY["mine"]
    fifth = fx.encoder_harmonic(4, order=5)
    assert fx.term_from_key(fifth.key).names == fifth.names


def test_terms_pickle_and_parse_from_their_keys(arm: ap.Arm) -> None:
    samples = Samples(arm, np.zeros((3, arm.n_axes)) + 0.3)
    for term in TERMS:
        back = pickle.loads(pickle.dumps(term))
        assert back == term == fx.term_from_key(term.key)
        if isinstance(term, fx.AngleTerm):
            np.testing.assert_array_equal(back.basis(samples), term.basis(samples))
    with pytest.raises(KeyError):
        fx.term_from_key("nonsense")


@pytest.mark.parametrize("which", ["aacmm7", "torso"])
def test_positive_lateral_compliance_makes_the_arm_sag(which: str) -> None:
    """Gravity pulls the arm down: a joint that gives way laterally (kx, ky > 0) lets the centre of
    mass of the whole arm drop (Pinocchio's centre of mass, every body turned about the joint's
    lateral axes by the term's tilts on its child side: independent of the moment's sign
    convention); the moment's third component, about the axis, is Samples.gravity."""
    import pinocchio as pin

    from aacmm_pin.model._chain import BatchedChain

    arm = ap.load_arm("aacmm7" if which == "aacmm7" else ROOT / "urdf" / "torso.urdf")
    model = arm.runtime_model()
    chain = BatchedChain(model)
    rng = np.random.default_rng(5)
    checked = 0
    for q in rng.uniform(-1.5, 1.5, (5, arm.n_axes)):
        samples = Samples(arm, q[None, :])
        qs = np.zeros(model.nq)
        qs[[model.joints[model.getJointId(n)].idx_q for n in arm.axis_names]] = q
        for axis in range(1, arm.n_axes + 1):
            if np.linalg.norm(samples.lateral_gravity[0, axis - 1]) < 0.5:  # N m: hardly loaded
                continue
            ext = {f"lateral_compliance[A{axis}]": np.array([1e-4, 1e-4])}
            params = ap.Parameters.nominal(arm).replace(extensions=ext)
            tilt = fx.forward.adjustment(params, samples, arm.n_axes).tilts[0, axis - 1]
            joint = model.getJointId(arm.axis_names[axis - 1])
            tilted = model.copy()
            turn = pin.SE3(pin.exp3(chain.basis(joint)[:, :2] @ tilt), np.zeros(3))
            for child in range(1, tilted.njoints):
                if tilted.parents[child] == joint:
                    tilted.jointPlacements[child] = turn * tilted.jointPlacements[child]
            tilted.inertias[joint] = turn.act(tilted.inertias[joint])
            z_before = pin.centerOfMass(model, model.createData(), qs)[2]
            z_after = pin.centerOfMass(tilted, tilted.createData(), qs)[2]
            assert z_after < z_before, (axis, tilt)
            checked += 1
    assert checked >= 10


def test_an_effect_may_not_take_a_built_in_name_unasked() -> None:
    """A plugin's effect named like a built-in would evaluate the built-in's keys: refused."""

    class Impostor(fx.Effect):
        name = "compliance"

        def candidates(self, arm: ap.Arm, samples: Samples) -> list[fx.Term]:
            return []

        def term(self, key: str) -> fx.Term | None:
            return None

    builtin = fx.LIBRARY["compliance"]
    with pytest.raises(ap.AacmmError, match="'compliance'.*taken by the effect of 'aacmm_pin'"):
        fx.register_effect(Impostor, "someone-elses-plugin")
    assert fx.LIBRARY["compliance"] is builtin
    try:
        fx.register_effect(Impostor, "someone-elses-plugin", replace=True)
        assert isinstance(fx.LIBRARY["compliance"], Impostor)
    finally:
        fx.register_effect(builtin, "aacmm_pin", replace=True)
    assert fx.LIBRARY["compliance"] is builtin
