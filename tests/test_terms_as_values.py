"""Terms as values: a calibration carries its extensions' terms, looked up once where it is made.

The key -> term lookup (:func:`aacmm_pin.effects.registry.term_from_key`, registered with the model
layer as :data:`aacmm_pin.model.parameters.TERM_LOOKUP`) runs where ``parameters.json`` is read or
parameters are built; every evaluation (predict, the Jacobians, IK, the runtime arm, identify with
terms, writing the file) uses the terms the parameters hold. The tests take the lookup away after
the parameters are made: any evaluation that still looked a key up would fail.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.effects import compliance, thermal
from aacmm_pin.effects.base import Term
from aacmm_pin.effects.calibrated import stylus_ik, stylus_jacobians
from aacmm_pin.model import parameters as model_parameters
from aacmm_pin.model.samples import Samples

KEYS = {"compliance[A2]": [2e-6], "thermal": [1e-5], "lateral_compliance[A3]": [1e-6, -1e-6]}


def _no_lookup(key: str) -> Term:
    raise AssertionError(f"{key!r} looked up on an evaluation path")


@pytest.fixture()
def written(arm: ap.Arm, tmp_path: Path) -> Path:
    """A parameters.json with three extensions (two effects' terms and a tilt term)."""
    path = tmp_path / "parameters.json"
    ap.write_parameters(ap.Parameters.nominal(arm).replace(extensions=KEYS), path)
    return path


def test_reading_makes_every_key_its_term(written: Path) -> None:
    params = ap.read_parameters(written)
    assert set(params.extension_terms) == set(KEYS)
    for key, term in params.extension_terms.items():
        assert isinstance(term, Term) and term.key == key
    assert [t.key for t, _ in params.term_values()] == list(KEYS)


def test_evaluations_use_the_terms_the_parameters_carry(arm: ap.Arm, written: Path,
                                                        tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    params = ap.read_parameters(written)
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (20, arm.n_axes))
    samples = Samples(arm, q, columns={"temp_c": np.full(20, 25.0)})
    before = ap.predict(arm, params, q, samples)
    monkeypatch.setattr(model_parameters, "TERM_LOOKUP", [_no_lookup])
    moved = params.replace(translation=np.array([1e-3, 0.0, 0.0]))  # a calibration made from it
    np.testing.assert_array_equal(ap.predict(arm, params, q, samples), before)
    assert ap.predict(arm, moved, q, samples).shape == (20, 3)
    stylus_jacobians(arm, params, q, "mt", samples, tilts=True)
    cold = params.replace(extensions={k: v for k, v in params.extensions.items() if k != "thermal"})
    stylus_ik(arm, cold, before[:3], np.random.default_rng(1))  # IK: no temperature column
    ap.CalibratedArm(arm, cold).position(q[0])
    ap.write_parameters(params, tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == written.read_bytes()


def test_identify_with_terms_looks_nothing_up(arm: ap.Arm, effects_sim: ap.Simulation,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """The fit's parameters at every evaluation carry the terms it estimates."""
    monkeypatch.setattr(model_parameters, "TERM_LOOKUP", [_no_lookup])
    cal = ap.identify(effects_sim.campaign, arm, "dh", extensions=(compliance(2), thermal()))
    assert set(cal.parameters.extension_terms) == {"compliance[A2]", "thermal"}
    assert cal.parameters.extension_terms["thermal"] == thermal()


def test_a_key_no_effect_knows_has_no_term_and_its_use_names_it(arm: ap.Arm) -> None:
    params = ap.Parameters.nominal(arm).replace(extensions={"gravity[A2]": [1.0]})
    assert params.extension_terms == {}
    with pytest.raises(KeyError, match=r"gravity\[A2\]"):
        ap.predict(arm, params, np.zeros((1, arm.n_axes)))
