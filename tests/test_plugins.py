"""Plugins the Python way: effects from a file (``--effects-file``) and from an installed package's
entry point (group ``aacmm_pin.effects``), named in ``parameters.json`` and required by every process
that reads it; each in fresh processes, as a user runs them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from tests.helpers import ENV, ROOT

# A user's effect: an angle error proportional to the gravity torque on the axis (a compliance
# under another name), written as a plugin would write it, against the public API only.
EFFECT_SOURCE = '''
"""A user's effect: {name}[An], an angle error of An proportional to the gravity torque on it."""
from functools import partial

import numpy as np

from aacmm_pin import AngleTerm, Effect


def _torque(axis, samples):
    return samples.gravity[:, axis - 1:axis]


def _variable(axis, samples):
    return f"gravity torque on A{{axis}} (N m)", samples.gravity[:, axis - 1]


def term(axis):
    return AngleTerm(f"{name}[A{{axis}}]", "{name}", (f"{name}[A{{axis}}].k",), (1e-5,),
                     "an angle error proportional to the gravity torque", axes=(axis,),
                     basis_of=partial(_torque, axis), variable_of=partial(_variable, axis))


class {cls}(Effect):
    name = "{name}"
    description = "a user's sag: angle error proportional to the gravity torque"

    def candidates(self, arm, samples):
        return [term(a) for a in (2, 4)]

    def term(self, key):
        for a in range(1, 10):
            if key == f"{name}[A{{a}}]":
                return term(a)
        return None
'''


def _cli(*args: str, pythonpath: str = "", cwd: Path | None = None
         ) -> subprocess.CompletedProcess[str]:
    """Run ``python -m aacmm_pin ARGS`` in a fresh process (``pythonpath`` before this checkout)."""
    env = dict(ENV)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env["PYTHONPATH"]
    return subprocess.run([sys.executable, "-m", "aacmm_pin", *args], capture_output=True,
                          text=True, env=env, timeout=300, cwd=cwd)


def _error_line(done: subprocess.CompletedProcess[str]) -> str:
    """Return the one line of a failed command's standard error (asserting it is one line)."""
    lines = [line for line in done.stderr.splitlines() if "still working" not in line]
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory, arm: ap.Arm) -> Path:
    """A small campaign (4 x 30 SPAT samples) of DH errors and gravity compliance, as CSVs."""
    folder = tmp_path_factory.mktemp("plugins") / "campaign"
    config = ap.SimulationConfig(seed=1, effects=("dh", "rtest", "compliance"),
                                 samples_per_location=30, bar_placements=1, samples_per_socket=5)
    ap.write_simulation(ap.simulate_campaign(arm, config), folder)
    return folder


@pytest.fixture(scope="module")
def effects_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Python file that registers the user's ``sag`` effect."""
    path = tmp_path_factory.mktemp("user") / "sag_effect.py"
    path.write_text(EFFECT_SOURCE.format(name="sag", cls="Sag")
                    + "\n\nfrom aacmm_pin import register_effect\n\nregister_effect(Sag)\n")
    return path


def test_effects_file_is_named_in_parameters_json_and_needed_to_read_it(
        campaign: Path, effects_file: Path, tmp_path: Path) -> None:
    """identify --terms with --effects-file writes "plugins" naming the file; predict without the
    file fails with one line naming the key and the file, with it applies the term."""
    cal = tmp_path / "cal"
    done = _cli("identify", str(campaign), "--model", "dh", "--terms", "sag[A2],sag[A4]",
                "--effects-file", str(effects_file), "--out", str(cal))
    assert done.returncode == 0, done.stderr
    params = json.loads((cal / "parameters.json").read_text())
    assert set(params["extensions"]) == {"sag[A2]", "sag[A4]"}
    assert params["plugins"] == {str(effects_file.resolve()): ["sag[A2]", "sag[A4]"]}

    readouts = campaign / "spat.csv"
    line = _error_line(_cli("predict", str(cal), str(readouts), "--out", str(tmp_path / "p.csv")))
    assert "sag[A2]" in line and str(effects_file.resolve()) in line and "--effects-file" in line
    assert not (tmp_path / "p.csv").exists()
    for command in (["validate", str(cal), str(campaign)],
                    ["iso10360", "euni", "--params", str(cal), str(campaign)],
                    ["view", str(cal), str(campaign), "--html", str(tmp_path / "v.html")]):
        line = _error_line(_cli(*command))  # every command that reads a calibration
        assert "sag[A2]" in line and str(effects_file.resolve()) in line, command

    done = _cli("predict", str(cal), str(readouts), "--out", str(tmp_path / "p.csv"),
                "--effects-file", str(effects_file))
    assert done.returncode == 0, done.stderr
    bare = json.loads((cal / "parameters.json").read_text())
    bare.pop("plugins")
    bare["extensions"] = {}
    (tmp_path / "bare.json").write_text(json.dumps(bare))
    (tmp_path / "calibrated.urdf").write_text((cal / "calibrated.urdf").read_text())
    assert _cli("predict", str(tmp_path / "bare.json"), str(readouts), "--out",
                str(tmp_path / "bare.csv")).returncode == 0
    with_sag = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)[:, -3:]
    plain = np.loadtxt(tmp_path / "bare.csv", delimiter=",", skiprows=1)[:, -3:]
    assert np.abs(with_sag - plain).max() > 1e-4  # mm: the file's terms are applied


def test_discover_tries_the_effects_of_a_file(campaign: Path, effects_file: Path,
                                              tmp_path: Path) -> None:
    """discover --effects accepts a name the --effects-file registered; its final model names the
    file as the plugin of the term it added."""
    done = _cli("discover", str(campaign), "--effects", "sag", "--max-steps", "1",
                "--effects-file", str(effects_file), "--out", str(tmp_path / "d"))
    assert done.returncode == 0, done.stderr
    assert "step 1: sag on A" in done.stdout
    params = json.loads((tmp_path / "d" / "parameters.json").read_text())
    keys = [k for k in params["extensions"] if k.startswith("sag[")]
    assert keys and params["plugins"] == {str(effects_file.resolve()): keys}
    line = _error_line(_cli("discover", str(campaign), "--effects", "sag",
                            "--out", str(tmp_path / "d2")))
    assert "unknown ['sag']" in line


def test_a_broken_effects_file_is_named(campaign: Path, tmp_path: Path) -> None:
    """A missing or failing effects file is one line naming it."""
    bad = tmp_path / "bad_effects.py"
    bad.write_text("raise RuntimeError('no\\nluck')\n")
    for path in (bad, tmp_path / "missing.py"):
        line = _error_line(_cli("discover", str(campaign), "--effects-file", str(path),
                                "--out", str(tmp_path / "d")))
        assert str(path) in line


def _distribution(folder: Path, name: str, module: str, source: str, entry: str) -> None:
    """Write an installed distribution as pip leaves it: ``name-0.1.dist-info`` and its module."""
    info = folder / f"{name}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[aacmm_pin.effects]\n{entry}\n")
    (folder / f"{module}.py").write_text(source)


def test_an_installed_entry_point_is_found_and_named(campaign: Path, tmp_path: Path) -> None:
    """An installed distribution's ``aacmm_pin.effects`` entry point is found without any option;
    its effect is recorded with the distribution's name as plugin; a process without it names it."""
    site = tmp_path / "site"
    _distribution(site, "myplug", "myplug", EFFECT_SOURCE.format(name="myeffect", cls="MyEffect"),
                  "myeffect = myplug:MyEffect")
    probe = ("from aacmm_pin.effects.registry import library, plugin_of; "
             "print(sorted(library()), plugin_of('myeffect'))")
    env = {**ENV, "PYTHONPATH": str(site) + os.pathsep + ENV["PYTHONPATH"]}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0 and out.stdout.strip().endswith("myplug"), out.stderr
    assert "'myeffect'" in out.stdout

    done = _cli("discover", str(campaign), "--effects", "myeffect", "--max-steps", "1",
                "--out", str(tmp_path / "d"), pythonpath=str(site))
    assert done.returncode == 0, done.stderr
    params = json.loads((tmp_path / "d" / "parameters.json").read_text())
    keys = [k for k in params["extensions"] if k.startswith("myeffect[")]
    assert keys and params["plugins"] == {"myplug": keys}
    readouts = str(campaign / "spat.csv")
    assert _cli("predict", str(tmp_path / "d"), readouts, "--out", str(tmp_path / "p.csv"),
                pythonpath=str(site)).returncode == 0
    line = _error_line(_cli("predict", str(tmp_path / "d"), readouts, "--out",
                            str(tmp_path / "q.csv")))
    assert keys[0] in line and "'myplug'" in line and "install the package myplug" in line


def test_a_plugin_that_fails_to_load_is_one_line_naming_it(campaign: Path, tmp_path: Path) -> None:
    """An entry point whose module raises gives one line naming the distribution."""
    site = tmp_path / "site"
    _distribution(site, "brokenplug", "brokenplug", "raise ImportError('needs\\nsomething')\n",
                  "broken = brokenplug:Broken")
    line = _error_line(_cli("discover", str(campaign), "--out", str(tmp_path / "d"),
                            pythonpath=str(site)))
    assert "'brokenplug'" in line and "ImportError: needs" in line


def test_parameters_json_keeps_no_plugins_for_built_in_terms(tmp_path: Path) -> None:
    """Built-in terms need no plugin: write_parameters drops a stale "plugins" entry."""
    arm = ap.load_arm()
    params = ap.Parameters.nominal(arm).replace(extensions={"compliance[A2]": [1e-6]},
                                                extra={"plugins": {"old": ["compliance[A2]"]}})
    ap.write_parameters(params, tmp_path / "p.json")
    assert "plugins" not in json.loads((tmp_path / "p.json").read_text())


def test_import_stays_lazy_with_the_extension_point() -> None:
    """``import aacmm_pin`` imports no effect module; the extension point resolves on first use."""
    code = ("import sys, aacmm_pin as ap; assert 'aacmm_pin.effects' not in sys.modules; "
            "from aacmm_pin.effects import base, registry; "
            "assert ap.Effect is base.Effect and ap.register_effect is registry.register_effect")
    done = subprocess.run([sys.executable, "-c", code], env=ENV, cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr


BAD_BASIS = {
    "nan": "return np.full((samples.n, 1), np.nan)",
    "shape": "return np.ones(3)",
    "raises": "raise ZeroDivisionError('division by zero in the user\\'s code')",
}


@pytest.mark.parametrize("fault, why", [("nan", "not finite"), ("shape", "shape (3,)"),
                                        ("raises", "raised ZeroDivisionError")])
def test_a_plugins_bad_output_is_one_line_naming_it(campaign: Path, tmp_path: Path, fault: str,
                                                    why: str) -> None:
    """A plugin's basis that gives NaN, a wrong shape or raises: one line naming the term, its
    effect and the plugin's file, exit 2; no file written (a NaN reached predict's file, a raise
    printed 60 lines of traceback)."""
    source = EFFECT_SOURCE.format(name="bent", cls="Bent").replace(
        "    return samples.gravity[:, axis - 1:axis]", "    " + BAD_BASIS[fault])
    path = tmp_path / "bent_effect.py"
    path.write_text(source + "\n\nfrom aacmm_pin import register_effect\n\nregister_effect(Bent)\n")
    out = tmp_path / "cal"
    line = _error_line(_cli("identify", str(campaign), "--model", "dh", "--terms", "bent[A2]",
                            "--effects-file", str(path), "--out", str(out)))
    assert "term bent[A2]" in line and "effect 'bent'" in line and str(path.resolve()) in line
    assert why in line
    assert not out.exists()


def test_a_replaced_built_in_is_not_read_back_as_the_built_in(campaign: Path, tmp_path: Path) -> None:
    """A calibration made with a plugin that replaced the built-in compliance names the plugin;
    read without it, the built-in (another model) is refused in one line naming both."""
    path = tmp_path / "my_compliance.py"
    path.write_text(EFFECT_SOURCE.format(name="compliance", cls="MyCompliance").replace(
        "samples.gravity[:, axis - 1:axis]", "2.0 * samples.gravity[:, axis - 1:axis]")
        + "\n\nfrom aacmm_pin import register_effect\n\nregister_effect(MyCompliance, "
          "replace=True)\n")
    cal = tmp_path / "cal"
    done = _cli("identify", str(campaign), "--model", "dh", "--terms", "compliance[A2]",
                "--effects-file", str(path), "--out", str(cal))
    assert done.returncode == 0, done.stderr
    params = json.loads((cal / "parameters.json").read_text())
    assert params["plugins"] == {str(path.resolve()): ["compliance[A2]"]}
    line = _error_line(_cli("predict", str(cal), str(campaign / "spat.csv"), "--out",
                            str(tmp_path / "p.csv")))
    assert "compliance[A2]" in line and str(path.resolve()) in line and "aacmm_pin" in line
    assert not (tmp_path / "p.csv").exists()
    done = _cli("predict", str(cal), str(campaign / "spat.csv"), "--effects-file", str(path),
                "--out", str(tmp_path / "p.csv"))
    assert done.returncode == 0, done.stderr
