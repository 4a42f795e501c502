"""The contract of every registered effect (built-in, installed plugin, and the example plugins').

Parametrised over :func:`aacmm_pin.effects.registry.library`, so that an effect added later is
checked without editing this file. For each effect, a few of its candidate terms on the shared
simulated samples (the effects campaign with temperature and time of ``tests/conftest.py``, and
samples of the two-armed torso) must:

(a) give columns (``term.columns``) equal to central differences of the modelled point
    (:func:`aacmm_pin.effects.calibrated.stylus_positions` in the MT-CS with the term's values
    perturbed, plus ``term.shift`` for measurement terms; a map term's nodes through the maps);
(b) keep their values through ``parameters.json`` and back exactly, the file naming the plugin of
    an effect that is not built in;
(c) ``predict`` the same stylus centres in a second process as in this one, to 1e-12 m;
(d) parse back from their key (``term_from_key``) and pickle; be ``in_model`` of the model they
    were ``added_to``.

An effect that proposes no candidate on any of the shared samples fails: a new effect comes with
data that shows it (add it to ``tests/conftest.py``). Effects in every start model
(``Effect.in_start``, the tool) propose no terms and are checked for that. The default run checks
a few terms per effect; ``-m slow`` every candidate of every effect on every sample set.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import os
import pickle
import subprocess
import sys
import textwrap
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.effects import parameters_file, registry
from aacmm_pin.effects.base import Effect, MapTerm, ModelSpec, Term, TiltTerm
from aacmm_pin.effects.calibrated import stylus_jacobians, stylus_positions
from aacmm_pin.model.encoder_map import EncoderMap
from aacmm_pin.model.samples import Samples
from tests.helpers import ENV, ROOT

EXAMPLE_PLUGINS = {
    "basetemp": (ROOT / "examples" / "05_plugin" / "aacmm_pin_basetemp.py", "temp_base_c", 26.0),
    "stylus_thermal": (ROOT / "examples" / "07_stylus_plugin" / "aacmm_pin_stylustemp.py",
                       "temp_probe_c", 30.0),
}
"""The example plugins' effects (an angle term, a frame term), held to the same contract: effect
-> (module, the column it reads, its last value on the samples, warming from 20 deg C)."""
EFFECTS = [name for name, effect in registry.library().items() if not effect.in_start]
START_EFFECTS = [name for name, effect in registry.library().items() if effect.in_start]
PER_EFFECT = 3
"""Terms checked per effect and sample set in the default run (the first, middle and last
candidate, each way of acting among them)."""

def rebuild(arm: ap.Arm, data: dict[str, np.ndarray]) -> Samples:
    """Return the Samples of the arrays of :func:`samples_arrays` (here and in the second process)."""
    from aacmm_pin.model.samples import Samples

    def get(key: str) -> np.ndarray | None:
        return data[key] if key in data else None

    kwargs = {"tool": get("tool"), "location": get("location")}
    columns = {k[len("column:"):]: data[k] for k in data if k.startswith("column:")}
    if columns:
        return Samples(arm, data["q"], get("temp"), get("t"), get("displacement"),
                       columns=columns, **kwargs)
    return Samples(arm, data["q"], get("temp"), get("t"), get("displacement"), **kwargs)


SECOND_PROCESS = '''
from __future__ import annotations
import json, sys
import numpy as np
import aacmm_pin as ap
from aacmm_pin.effects.registry import load_effect_file

job = json.loads(open(sys.argv[1]).read())
for path in job["effect_files"]:
    load_effect_file(path)
out = {}
for case in job["cases"]:
    params = ap.read_parameters(case["params"])
    arm = ap.load_arm(params.arm)
    with np.load(case["samples"]) as npz:
        samples = rebuild(arm, {k: npz[k] for k in npz.files})
    out[case["id"]] = ap.predict(arm, params, samples.q, samples, tool=samples.tool)
np.savez(sys.argv[2], **out)
'''.replace("\nimport json", "\n" + textwrap.dedent(inspect.getsource(rebuild)) + "\nimport json", 1)


def samples_arrays(samples: Samples) -> dict[str, np.ndarray]:
    """Return the arrays that define the samples (readouts and their per-sample columns)."""
    out = {"q": samples.q}
    for name in ("temp", "t", "displacement", "tool", "location"):
        if getattr(samples, name) is not None:
            out[name] = np.asarray(getattr(samples, name))
    for name, values in (getattr(samples, "columns", None) or {}).items():
        out[f"column:{name}"] = np.asarray(values)
    return out


class Case:
    """One term on one sample set: the arm, parameters holding the term's values, the samples."""

    def __init__(self, source: str, arm: ap.Arm, params: ap.Parameters, samples: Samples,
                 term: Term):
        self.source, self.arm, self.samples, self.term = source, arm, samples, term
        rng = np.random.default_rng(zlib.crc32(f"{source}:{term.key}".encode()))
        self.size = np.broadcast_to(term.sizes(arm.sizes), (self.n_values(params),)).astype(float)
        self.values = rng.normal(0.0, 1.0, self.size.shape) * self.size
        self.params = self.with_values(params, self.values)

    @property
    def id(self) -> str:
        """``source:key``."""
        return f"{self.source}:{self.term.key}"

    def n_values(self, params: ap.Parameters) -> int:
        """Number of the term's values (a map's: its nodes)."""
        return params.map(self.term.axis).n_nodes if isinstance(self.term, MapTerm) \
            else len(self.term.names)

    def with_values(self, params: ap.Parameters, values: np.ndarray) -> ap.Parameters:
        """Return ``params`` with the term's values (in the extensions, or the axis' map)."""
        if isinstance(self.term, MapTerm):
            return params.replace(encoder_maps={**params.encoder_maps, self.term.axis: EncoderMap(
                np.asarray(values, dtype=float), params.step_deg)})
        return params.replace(extensions={**params.extensions, self.term.key: values})

    def point(self, values: np.ndarray) -> np.ndarray:
        """The modelled point (MT-CS, m, shape (N, 3)) with the term's values ``values``."""
        params = self.with_values(self.params, values)
        pos = stylus_positions(self.arm, params, self.samples.q, frame="mt", samples=self.samples,
                               tool=self.samples.tool)
        shift = None if isinstance(self.term, MapTerm) else self.term.shift(values, self.samples)
        return pos if shift is None else pos + shift


# ------------------------------------------------------------------ the shared sample sets
@pytest.fixture(scope="module")
def torso() -> ap.Arm:
    """The two-armed torso (a tree: 15 axes, two tools)."""
    return ap.load_arm(str(ROOT / "urdf" / "torso.urdf"))


def _torso_samples(torso: ap.Arm) -> tuple[ap.Parameters, Samples]:
    """40 postures of the torso within its limits, both tools, warming, 4 groups, a displacement."""
    rng = np.random.default_rng(11)
    n = 40
    q = rng.uniform(torso.joint_limits[:, 0], torso.joint_limits[:, 1], (n, torso.n_axes))
    dh = {k: v + rng.normal(0.0, 1e-4) for k, v in torso.nominal_errors.items()}
    params = ap.Parameters.nominal(torso).replace(dh=dh, arm=str(torso.source))
    samples = Samples(torso, q, temp=np.linspace(20.0, 24.0, n), t=np.arange(n) * 2.0,
                      displacement=rng.normal(0.0, 5e-6, (n, 3)), tool=rng.integers(0, 2, n),
                      location=np.repeat(np.arange(1, 5), n // 4))
    return params, samples


@pytest.fixture(scope="module")
def sources(arm: ap.Arm, effects_sim: ap.Simulation, torso: ap.Arm
            ) -> dict[str, tuple[ap.Arm, ap.Parameters, Samples]]:
    """Sample sets by name: the shared effects campaign's SPATs and the torso's postures."""
    spat = effects_sim.campaign.spat
    assert spat is not None
    truth = effects_sim.truth.replace(extensions={})
    return {"effects_sim": (arm, truth, Samples.of_spat(arm, spat)),
            "torso": (torso, *_torso_samples(torso))}


def _pick(candidates: list[Term], k: int | None) -> list[Term]:
    """Return ``k`` spread candidates, each way of acting among them (all of them: ``k`` None)."""
    if k is None or len(candidates) <= k:
        return list(candidates)
    index = {0, len(candidates) // 2, len(candidates) - 1}
    for kind in dict.fromkeys(type(t) for t in candidates):
        index.add(next(i for i, t in enumerate(candidates) if type(t) is kind))
    return [candidates[i] for i in sorted(index)]


def _cases(effect: Effect, sources: dict[str, Any], exhaustive: bool = False) -> list[Case]:
    """Return the checked terms of an effect: a few on each sample set where it has candidates."""
    out = []
    for name, (arm, params, samples) in sources.items():
        candidates = effect.candidates(arm, samples)
        out += [Case(name, arm, params, samples, t)
                for t in _pick(candidates, None if exhaustive else PER_EFFECT)]
    if not out:
        pytest.fail(f"effect {effect.name!r} proposes no candidate term on any shared sample set "
                    f"({', '.join(sources)}): add samples that show it to tests/conftest.py")
    return out


@pytest.fixture(scope="module")
def example_effect(sources: dict[str, Any]) -> Iterator[dict[str, Any]]:
    """The example plugins' effects, registered from their files, and the effects campaign with
    their columns."""
    before = dict(registry.LIBRARY)
    arm, params, samples = sources["effects_sim"]
    data = samples_arrays(samples)
    for path, column, last in EXAMPLE_PLUGINS.values():
        registry.load_effect_file(path)
        data[f"column:{column}"] = np.linspace(20.0, last, samples.n)
    try:
        yield {"effects_sim": (arm, params, rebuild(arm, data))}
    finally:
        registry.LIBRARY.clear()
        registry.LIBRARY.update(before)


def _effect_sources(name: str, request: pytest.FixtureRequest) -> tuple[Effect, dict[str, Any]]:
    if name in EXAMPLE_PLUGINS:
        extra = request.getfixturevalue("example_effect")
        return registry.library()[name], extra
    return registry.library()[name], request.getfixturevalue("sources")


ALL = [*EFFECTS, *(pytest.param(name, id=f"example-{name}") for name in EXAMPLE_PLUGINS
                   if name not in EFFECTS)]


# ------------------------------------------------------------------ (a) columns
@pytest.mark.parametrize("name", ALL)
def test_columns_equal_central_differences(name: str, request: pytest.FixtureRequest) -> None:
    """Each term's columns are the central differences of the modelled point in its values."""
    effect, sources = _effect_sources(name, request)
    for case in _cases(effect, sources):
        _check_columns(case)


@pytest.mark.slow
@pytest.mark.parametrize("name", ALL)
def test_columns_of_every_candidate(name: str, request: pytest.FixtureRequest) -> None:
    """Every candidate of the effect on every sample set: columns against central differences."""
    effect, sources = _effect_sources(name, request)
    for case in _cases(effect, sources, exhaustive=True):
        _check_columns(case, nodes=None)


def _check_columns(case: Case, nodes: int | None = 4) -> None:
    """Compare ``term.columns`` with central differences of :meth:`Case.point`.

    Step ``h = 1e-3`` of each value's plausible size: the truncation error ``h^2 |f'''| / 6`` is
    then ~1e-6 of the column's size or less (the model is at most smooth in an angle of ~1e-3 of
    a plausible error), and the rounding error ``~10 eps max|p| / h`` (p ~ 1 m).
    """
    term, samples = case.term, case.samples
    stylus = stylus_jacobians(case.arm, case.params, samples.q, frame="mt", samples=samples,
                              tool=samples.tool, tilts=isinstance(term, TiltTerm))
    analytic = term.columns(samples, stylus, case.params)
    assert analytic.shape == (samples.n, 3, case.values.size), case.id
    which = np.arange(case.values.size)
    if isinstance(term, MapTerm) and nodes is not None:  # a few of the nodes the samples touch
        touched = np.flatnonzero(np.abs(analytic).max(axis=(0, 1)) > 0)
        which = touched[np.linspace(0, touched.size - 1, min(nodes, touched.size)).astype(int)]
    scale = np.abs(case.point(case.values)).max()
    for j in which:
        h = 1e-3 * case.size[j]
        step = np.zeros_like(case.values)
        step[j] = h
        fd = (case.point(case.values + step) - case.point(case.values - step)) / (2 * h)
        col = analytic[:, :, j]
        tol = 1e-6 * np.abs(col).max() + 10 * np.finfo(float).eps * scale / h
        np.testing.assert_allclose(col, fd, rtol=0, atol=tol, err_msg=f"{case.id} value {j}")


# ------------------------------------------------------------------ (b) parameters.json
@pytest.mark.parametrize("name", ALL)
def test_values_round_trip_through_parameters_json(name: str, request: pytest.FixtureRequest,
                                                   tmp_path: Path) -> None:
    """The term's values come back from parameters.json exactly; the file names its plugin."""
    effect, sources = _effect_sources(name, request)
    for k, case in enumerate(_cases(effect, sources)):
        path = tmp_path / f"p{k}.json"
        parameters_file.write_parameters(case.params, path)
        back = parameters_file.read_parameters(path)
        if isinstance(case.term, MapTerm):
            np.testing.assert_array_equal(back.map(case.term.axis).values, case.values)
            continue
        np.testing.assert_array_equal(back.extensions[case.term.key], case.values)
        plugins = json.loads(path.read_text()).get("plugins", {})
        assert plugins == registry.plugins_of([case.term]), case.id
        assert (registry.plugin_of(effect.name) == registry.BUILTIN) == (plugins == {})


# ------------------------------------------------------------------ (c) a second process
@pytest.fixture(scope="module")
def second_process(sources: dict[str, Any], tmp_path_factory: pytest.TempPathFactory
                   ) -> dict[str, np.ndarray]:
    """``predict`` of every default case of every registered effect, in one second process."""
    folder = tmp_path_factory.mktemp("contract")
    cases = [c for name in EFFECTS if name not in EXAMPLE_PLUGINS
             for c in _cases(registry.library()[name], sources)]
    return _predict_elsewhere(cases, folder, [])


def _predict_elsewhere(cases: list[Case], folder: Path, effect_files: list[str]
                       ) -> dict[str, np.ndarray]:
    job: dict[str, Any] = {"effect_files": effect_files, "cases": []}
    for k, case in enumerate(cases):
        parameters_file.write_parameters(case.params, folder / f"p{k}.json")
        np.savez(folder / f"s{k}.npz", **samples_arrays(case.samples))
        job["cases"].append({"id": case.id, "params": str(folder / f"p{k}.json"),
                             "samples": str(folder / f"s{k}.npz")})
    (folder / "job.json").write_text(json.dumps(job))
    done = subprocess.run([sys.executable, "-c", SECOND_PROCESS, str(folder / "job.json"),
                           str(folder / "out.npz")], env=ENV, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    with np.load(folder / "out.npz") as out:
        return {k: out[k] for k in out.files}


@pytest.mark.parametrize("name", ALL)
def test_predict_in_a_second_process_is_this_ones(name: str, request: pytest.FixtureRequest,
                                                  tmp_path: Path) -> None:
    """predict from parameters.json in a fresh process equals predict here to 1e-12 m."""
    effect, sources = _effect_sources(name, request)
    cases = _cases(effect, sources)
    there = (_predict_elsewhere(cases, tmp_path, [str(EXAMPLE_PLUGINS[name][0])])
             if name in EXAMPLE_PLUGINS
             else request.getfixturevalue("second_process"))
    for k, case in enumerate(cases):
        parameters_file.write_parameters(case.params, tmp_path / f"here{k}.json")
        params = parameters_file.read_parameters(tmp_path / f"here{k}.json")
        samples = rebuild(case.arm, samples_arrays(case.samples))
        here = ap.predict(case.arm, params, samples.q, samples, tool=samples.tool)
        np.testing.assert_allclose(there[case.id], here, rtol=0, atol=1e-12, err_msg=case.id)
        if not isinstance(case.term, MapTerm) and case.term.shift(case.values, samples) is None:
            plain = ap.predict(case.arm, params.replace(extensions={}), samples.q, samples,
                               tool=samples.tool)
            assert np.abs(here - plain).max() > 0, f"{case.id}: predict ignores the term"


# ------------------------------------------------------------------ (d) identity and model state
@pytest.mark.parametrize("name", ALL)
def test_terms_parse_from_their_keys_pickle_and_join_a_model(name: str,
                                                             request: pytest.FixtureRequest
                                                             ) -> None:
    """term_from_key(key) == term (extension terms), terms pickle, and a term added to an empty
    model is in it, and not in the empty model."""
    effect, sources = _effect_sources(name, request)
    empty = ModelSpec(use_rtest=False)
    for case in _cases(effect, sources):
        term = case.term
        assert term.effect == effect.name, case.id
        if term.is_extension:
            assert registry.term_from_key(term.key) == term, case.id
            assert effect.term(term.key) == term, case.id
            assert len(term.names) == len(term.plausible) == case.values.size, case.id
        back = pickle.loads(pickle.dumps(term))
        assert back == term and hash(back) == hash(term), case.id
        if hasattr(term, "basis"):
            np.testing.assert_array_equal(back.basis(case.samples), term.basis(case.samples))
        assert not term.in_model(empty), case.id
        added = term.added_to(empty)
        assert term.in_model(added), case.id
        assert term.added_to(added) == added, case.id  # adding it again changes nothing


@pytest.mark.parametrize("name", START_EFFECTS)
def test_effects_of_every_start_model_propose_no_terms(name: str, sources: dict[str, Any]
                                                       ) -> None:
    """An effect that every start model has (the tool) proposes no candidate and owns no key."""
    effect = registry.library()[name]
    for arm, _, samples in sources.values():
        assert effect.candidates(arm, samples) == []


def test_every_registered_effect_is_checked() -> None:
    """The contract's parameter lists are the registry's effects (a new one is checked too)."""
    assert set(EFFECTS) | set(START_EFFECTS) == set(registry.library()) - set(EXAMPLE_PLUGINS)
    assert {"encoder", "compliance", "lateral_compliance", "thermal", "backlash", "crosstalk",
            "rtest"} <= set(EFFECTS)


# ------------------------------------------------------------------ (e) the contract at run time
BASETEMP = "basetemp"
"""Example 05's effect (an angle term on the column temp_base_c)."""
BASETEMP_FILE = ROOT / "examples" / "05_plugin" / "aacmm_pin_basetemp.py"
"""Example 05's plugin module, as its distribution installs it."""
# A plugin whose term gives Jacobian columns but no forward change (issue 37: accepted by
# discover, fitted to 18.3 ppm/K for a true 8 while the fit RMS rose): its ``adjust`` adds nothing.
GHOST_SOURCE = '''
"""A plugin's effect whose term has Jacobian columns but no forward change."""
from dataclasses import dataclass
from functools import partial

from aacmm_pin import AngleTerm, Effect, register_effect


@dataclass(frozen=True, eq=False)
class ColumnsOnly(AngleTerm):
    def adjust(self, values, samples, out):
        """Nothing: the model's points ignore the term, its columns do not."""


def _torque(axis, samples):
    return samples.gravity[:, axis - 1:axis]


def _variable(axis, samples):
    return f"gravity torque on A{axis} (N m)", samples.gravity[:, axis - 1]


def ghost(axis):
    return ColumnsOnly(f"ghost[A{axis}]", "ghost", (f"ghost[A{axis}].k",), (1e-5,),
                       "an angle error proportional to the gravity torque, columns only",
                       axes=(axis,), basis_of=partial(_torque, axis),
                       variable_of=partial(_variable, axis))


class Ghost(Effect):
    name = "ghost"
    description = "columns without a forward change"

    def candidates(self, arm, samples):
        return [ghost(a) for a in (2, 3)]

    def term(self, key):
        for a in range(1, 10):
            if key == f"ghost[A{a}]":
                return ghost(a)
        return None


register_effect(Ghost)
'''


def _cli(*args: str, pythonpath: str = "") -> subprocess.CompletedProcess[str]:
    """Run ``python -m aacmm_pin ARGS`` in a fresh process (``pythonpath`` before this checkout)."""
    env = dict(ENV)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env["PYTHONPATH"]
    return subprocess.run([sys.executable, "-m", "aacmm_pin", *args], capture_output=True,
                          text=True, env=env, timeout=600)


def _error_line(done: subprocess.CompletedProcess[str]) -> str:
    """Return the one line of a failed command's standard error (asserting it is one line)."""
    lines = [line for line in done.stderr.splitlines() if "still working" not in line]
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory: pytest.TempPathFactory, arm: ap.Arm) -> Path:
    """A small campaign (4 x 15 SPAT samples) of DH errors and gravity compliance, as CSVs,
    without the example plugin's column temp_base_c."""
    folder = tmp_path_factory.mktemp("contract_cli") / "campaign"
    config = ap.SimulationConfig(seed=1, effects=("dh", "rtest", "compliance"),
                                 samples_per_location=15, bar_placements=1, samples_per_socket=5)
    ap.write_simulation(ap.simulate_campaign(arm, config), folder)
    assert "temp_base_c" not in (folder / "spat.csv").read_text().splitlines()[0]
    return folder


def test_columns_without_a_forward_change_are_refused_in_identify_and_discover(
        campaign_folder: Path, tmp_path: Path) -> None:
    """A plugin term whose columns disagree with its forward change: identify --terms and
    discover refuse it in one line naming the term, its effect and the plugin (exit 2), and write
    no model."""
    plugin = tmp_path / "ghost_effect.py"
    plugin.write_text(GHOST_SOURCE)
    for command in (["identify", str(campaign_folder), "--model", "dh", "--terms", "ghost[A2]"],
                    ["discover", str(campaign_folder), "--effects", "ghost", "--max-steps", "1"]):
        out = tmp_path / command[0]
        line = _error_line(_cli(*command, "--effects-file", str(plugin), "--out", str(out)))
        assert "term ghost[A" in line and "effect 'ghost'" in line, line
        assert str(plugin.resolve()) in line and "forward change" in line, line
        assert not (out / "parameters.json").exists(), command[0]


def test_the_run_time_check_refuses_wrong_columns_and_passes_right_ones(
        sources: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """check_term: columns without a forward change and columns 1 % off are refused; the same
    term with its forward change passes; check_once checks a term once per process."""
    from aacmm_pin.effects import contract
    from aacmm_pin.effects.builtin.compliance import compliance

    arm, params, samples = sources["effects_sim"]
    right = compliance(2)
    values = {right.key: np.asarray(right.plausible)}
    at = params.replace(extensions=values)
    contract.check_term(right, samples, at)

    @dataclasses.dataclass(frozen=True, eq=False)
    class Scaled(type(right)):  # type: ignore[misc]
        factor: float = 1.0

        def adjust(self, values: np.ndarray, samples: Samples, out: Any) -> None:
            if self.factor:
                super().adjust(values / self.factor, samples, out)

    for factor, why in ((0.0, "central differences up to 0"), (1.01, "apart by")):
        wrong = Scaled(right.key, right.effect, right.names, right.plausible, right.description,
                       axes=right.axes, basis_of=right.basis_of, variable_of=right.variable_of,
                       factor=factor)
        with pytest.raises(contract.ContractBroken, match=why) as info:
            contract.check_term(wrong, samples, at)
        assert "\n" not in str(info.value) and f"term {right.key}" in str(info.value)
        assert "effect 'compliance'" in str(info.value)

    calls: list[str] = []
    monkeypatch.setattr(contract, "check_term", lambda term, *args: calls.append(term.key))
    fresh = dataclasses.replace(right, key="compliance[A2]#once")
    for _ in range(3):
        contract.check_once([fresh], samples, at)
    assert calls == ["compliance[A2]#once"]


@pytest.mark.parametrize("name", ALL)
def test_the_run_time_check_passes_every_effects_terms(name: str,
                                                       request: pytest.FixtureRequest) -> None:
    """The check that identify and discover run on a term's first use passes each term checked
    above (a few per effect and sample set: the torso's two tools, every way of acting)."""
    from aacmm_pin.effects import contract

    effect, sources = _effect_sources(name, request)
    for case in _cases(effect, sources):
        contract.check_term(case.term, case.samples, case.params)


def test_samples_without_an_effects_column_leave_it_out(sources: dict[str, Any],
                                                        example_effect: dict[str, Any]) -> None:
    """Samples without a declared column: the effect is left out and listed, never asked (its
    candidates would raise); with the column it is kept. A missing column is a KeyError too."""
    from aacmm_pin.effects.contract import LeftOut, usable_effects

    arm, _, plain = sources["effects_sim"]
    _, _, warm = example_effect["effects_sim"]
    effect = registry.library()[BASETEMP]
    with pytest.raises(KeyError, match=r"^no column 'temp_base_c' in the samples"):
        plain.column("temp_base_c")
    with pytest.raises(ap.AacmmError):
        plain.column("temp_base_c")
    kept, left = usable_effects([registry.library()["compliance"], effect], plain)
    assert [e.name for e in kept] == ["compliance"]
    assert left == [LeftOut(BASETEMP, ("temp_base_c",))]
    assert str(left[0]) == "basetemp (no column temp_base_c)"
    kept, left = usable_effects([effect], warm)
    assert kept == [effect] and left == [] and effect.candidates(arm, warm)
    no_disp = Samples(arm, plain.q, temp=plain.temp)
    assert usable_effects([registry.library()["rtest"]], no_disp)[1] == [
        LeftOut("rtest", ("dx_mm", "dy_mm", "dz_mm"))]


def test_discover_with_the_example_plugin_installed_lists_it_as_left_out(
        campaign_folder: Path, tmp_path: Path) -> None:
    """Example 05's plugin installed (its entry point), discover on a campaign without
    temp_base_c runs and lists the effect as left out (it stopped every discover before)."""
    site = tmp_path / "site"
    info = site / "aacmm_pin_basetemp-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: aacmm-pin-basetemp\n"
                                   "Version: 0.1.0\n")
    (info / "entry_points.txt").write_text("[aacmm_pin.effects]\n"
                                           "basetemp = aacmm_pin_basetemp:BaseTemperature\n")
    (site / BASETEMP_FILE.name).write_text(BASETEMP_FILE.read_text())
    out = tmp_path / "d"
    done = _cli("discover", str(campaign_folder), "--max-steps", "1", "--out", str(out),
                pythonpath=str(site))
    assert done.returncode == 0, done.stderr
    listed = [line for line in done.stdout.splitlines() if line.startswith("left out: ")]
    assert len(listed) == 1 and "basetemp (no column temp_base_c)" in listed[0], done.stdout
    result = json.loads((out / "discovery.json").read_text())
    assert {"effect": "basetemp", "missing_columns": ["temp_base_c"]} in result["left_out"]
    assert "basetemp" in result["library"]  # installed, registered, and not asked


class _Asks(Effect):
    """An effect that reads a column and fails loudly if asked anything on samples without it."""

    name = "asks"
    reads = ("temp_nowhere_c",)

    def candidates(self, arm: ap.Arm, samples: Samples) -> list[Term]:
        raise AssertionError("asked for candidates on samples without temp_nowhere_c")

    def term(self, key: str) -> Term | None:
        return None

    def variables(self, arm: ap.Arm, samples: Samples) -> list[ap.Variable]:
        raise AssertionError("asked for variables on samples without temp_nowhere_c")


def test_the_residual_scan_asks_no_effect_without_its_column(sources: dict[str, Any]) -> None:
    """The residual scan's variables come only from effects whose declared columns exist."""
    from aacmm_pin.analyses.residual_scan import _variables

    _, _, samples = sources["effects_sim"]
    names = [v.name for v in _variables(samples, None, [registry.library()["thermal"], _Asks()])]
    assert "temperature" in names
