"""parameters.json: round trip, the shared truth file, and clear errors for bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aacmm_pin.errors import FileFormatError
from aacmm_pin.model.arm import load_arm
from aacmm_pin.model.encoder_map import EncoderMap
from aacmm_pin.model.parameters import (
    Parameters,
    check_against_arm,
    read_parameters,
    rotation_abc,
    write_parameters,
)
from tests.helpers import SAMPLE, d_a, d_b, d_c


def test_round_trip(tmp_path):
    """Writing then reading gives the same values to the last bit, extra keys kept."""
    rng = np.random.default_rng(0)
    arm = load_arm()
    params = Parameters.nominal(arm).replace(
        dh={n: rng.normal() * 1e-4 for n in arm.error_names}, tool=rng.normal(size=3),
        rotation_abc=rng.normal(size=3), translation=rng.normal(size=3),
        encoder_maps={3: EncoderMap(rng.normal(size=72))}, extra={"effects": {"x": 1}})
    write_parameters(params, tmp_path / "parameters.json")
    again = read_parameters(tmp_path)  # a folder holding parameters.json works too
    assert again.dh == params.dh and again.extra == params.extra
    np.testing.assert_array_equal(again.tool, params.tool)
    np.testing.assert_array_equal(again.rotation_abc, params.rotation_abc)
    assert again.encoder_maps == params.encoder_maps


def test_rotation_is_eq4_order():
    """The r-CS -> MT-CS rotation is D_b(beta0) D_a(alpha0) D_c(gamma0)."""
    abc = np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(rotation_abc(abc), (d_b(-0.2) @ d_a(0.1) @ d_c(0.3))[:3, :3],
                               atol=1e-15)


@pytest.mark.skipif(not SAMPLE.is_dir(), reason="shared sample campaign not beside the project")
def test_reads_independent_truth_file():
    """The sample campaign's truth.json (written by independent code) reads and fits the arm."""
    params = read_parameters(SAMPLE / "truth.json")
    check_against_arm(params, load_arm(params.arm))
    assert sorted(params.encoder_maps) == list(range(1, 8)) and "effects" in params.extra


def test_json_syntax_error_has_line_and_column(tmp_path):
    """Broken JSON is reported with its line and column."""
    path = tmp_path / "parameters.json"
    path.write_text('{\n  "arm": "aacmm7",\n  "dh": {,}\n}\n')
    with pytest.raises(FileFormatError, match=r"parameters.json:3: column 'char 10'"):
        read_parameters(path)


def test_bad_fields_are_all_listed(tmp_path):
    """Every bad field is named in one error: a NaN, a short tool, a map of the wrong size."""
    path = tmp_path / "parameters.json"
    path.write_text(json.dumps({"arm": "aacmm7", "dh": {"dx21": "x"}, "tool": [0, 0],
                                "encoder_maps": {"axes": {"2": [0.0] * 70}}}))
    with pytest.raises(FileFormatError) as info:
        read_parameters(path)
    text = str(info.value)
    assert "3 problems" in text
    for key in ("dh.dx21", "'tool'", "encoder_maps.axes.2"):
        assert key in text


def test_parameters_that_do_not_fit_the_arm(tmp_path):
    """Missing and unknown DH names and out-of-range axes are named against the arm."""
    arm = load_arm()
    dh = dict(arm.nominal_errors)
    dh.pop("a76")
    dh["zz99"] = 0.0
    params = Parameters(arm="aacmm7", dh=dh, tool=np.zeros(3),
                        encoder_maps={9: EncoderMap.zero()})
    with pytest.raises(FileFormatError) as info:
        check_against_arm(params, arm)
    assert {"dh.zz99", "dh.a76", "encoder_maps.axes.9"} <= {p.column for p in info.value.problems}


@pytest.mark.parametrize("maps, key", [({"step_deg": 0, "axes": {}}, "encoder_maps.step_deg"),
                                       ({"step_deg": 5.0, "axes": [[0.0] * 72]}, "encoder_maps.axes")])
def test_bad_map_section_is_named(tmp_path, maps, key):
    """A zero step or a list instead of an axis object is a named problem, not a crash."""
    path = tmp_path / "parameters.json"
    path.write_text(json.dumps({"arm": "aacmm7", "dh": {}, "tool": [0, 0, -0.12],
                                "encoder_maps": maps}))
    with pytest.raises(FileFormatError, match=key.replace(".", r"\.")):
        read_parameters(path)


def test_implausible_values_are_refused(tmp_path):
    """Values beyond +-100 m or rad (fuzz: a tool of -1e300 m predicted points 1e300 m away) are
    refused, each named; every field that holds lengths or angles is checked."""
    arm = load_arm()
    good = Parameters.nominal(arm).to_dict()
    path = tmp_path / "parameters.json"
    for key, change in (("tool", {"tool": [-1e300, 0, 0]}),
                        ("dh.dx21", {"dh": {**good["dh"], "dx21": 1e3}}),
                        ("base_to_mt.translation",
                         {"base_to_mt": {"rotation_abc": [0, 0, 0], "translation": [0, 0, -5e4]}}),
                        ("encoder_maps.axes.2",
                         {"encoder_maps": {"step_deg": 5.0, "axes": {"2": [1e9] * 72}}})):
        path.write_text(json.dumps({**good, **change}))
        with pytest.raises(FileFormatError, match="not a calibration value") as info:
            read_parameters(path)
        assert key in str(info.value)
    path.write_text(json.dumps({**good, "tool": [0.0, 0.0, -99.0]}))  # large but within the limit
    assert read_parameters(path).tool[2] == -99.0


def test_numbers_given_as_text_or_booleans_are_refused(tmp_path):
    """numpy reads ["0", "0", "0.001"] and true as numbers: a tool of strings was accepted and
    moved every point by 0.12 m (fuzz, issue 14). Lists must hold JSON numbers."""
    good = Parameters.nominal(load_arm()).to_dict()
    path = tmp_path / "parameters.json"
    for key, change in (("tool", {"tool": [0.0, 0.0, "0.001"]}),
                        ("base_to_mt.rotation_abc",
                         {"base_to_mt": {"rotation_abc": [True, 0, 0], "translation": [0, 0, 0]}}),
                        ("encoder_maps.axes.3",
                         {"encoder_maps": {"step_deg": 5.0, "axes": {"3": ["0"] * 72}}})):
        path.write_text(json.dumps({**good, **change}))
        with pytest.raises(FileFormatError, match="list of") as info:
            read_parameters(path)
        assert key in str(info.value)
