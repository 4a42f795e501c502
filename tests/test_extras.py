"""The runtime install (``pip install .``) without the extras: viewer, figures, serial ports, yourdfpy."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from aacmm_pin.extras import DISTRIBUTIONS, EXTRAS
from tests.helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]
BLOCKED = ("meshcat", "matplotlib", "serial", "yourdfpy", "trimesh", "IPython")
"""The modules of the extras and the heaviest of what they pull in (trimesh, IPython)."""

BLOCKER = f"""
import importlib.abc, sys

class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in {BLOCKED!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, Blocker())
"""
"""Python that makes the extras' modules uninstalled for the rest of the process."""


def _pyproject() -> dict:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11
    with open(ROOT / "pyproject.toml", "rb") as f:
        return tomllib.load(f)["project"]


def _name(requirement: str) -> str:
    return re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower()


def test_core_dependencies_leave_out_the_extras():
    """pyproject's core dependencies list neither meshcat, matplotlib, pyserial nor yourdfpy."""
    core = {_name(r) for r in _pyproject()["dependencies"]}
    assert not core & {"meshcat", "matplotlib", "pyserial", "yourdfpy", "trimesh", "ipython"}, core
    assert {"pin", "numpy", "scipy", "lxml"} <= core


def test_every_extra_installs_its_modules_and_all_and_test_pull_them_all():
    """Each extra of extras.EXTRAS installs its modules; `all` names every extra, `test` pulls `all`."""
    optional = _pyproject()["optional-dependencies"]
    for extra, modules in EXTRAS.items():
        names = {_name(r) for r in optional[extra]}
        assert {DISTRIBUTIONS.get(m, m) for m in modules} <= names, extra
    (everything,) = optional["all"]
    assert set(everything.partition("[")[2].rstrip("]").split(",")) == set(EXTRAS)
    assert "aacmm_pin[all]" in optional["test"]


def _run_blocked(script: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", BLOCKER + textwrap.dedent(script)], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=300)


def test_without_extras_a_node_predicts_and_the_commands_say_what_is_missing(tmp_path):
    """With the extras' modules not installed: load, read, predict (API and CLI), identify, validate
    and discover work (no figures, said in one line); view, acquire and Arm.urdf_robot fail in one
    line naming the extra."""
    assert run_cli(["simulate", str(tmp_path / "c"), "--samples-per-location", "15",
                    "--samples-per-socket", "5"])[0] == 0  # any size: the messages are tested
    done = _run_blocked("""
        import contextlib, io, sys
        import numpy as np
        import aacmm_pin as ap
        from aacmm_pin.cli import main

        assert main(["identify", "c", "--out", "cal", "--model", "dh"]) == 0
        arm = ap.load_arm()
        cal = ap.read_calibration("cal")
        q = np.radians([[10, 20, -30, 40, 50, -60, 70]])
        assert ap.predict(arm, cal.parameters, q).shape == (1, 3)
        assert np.allclose(ap.load_calibrated("cal").position(q),  # the runtime object
                           ap.predict(arm, cal.parameters, q), atol=1e-12)
        with open("r.csv", "w") as f:
            f.write("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\\n10,20,-30,40,50,-60,70\\n")
        assert main(["predict", "cal", "r.csv", "--out", "p.csv"]) == 0
        assert main(["validate", "cal", "c"]) == 0
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert main(["discover", "c", "--out", "disc", "--max-steps", "1"]) == 0
        print(out.getvalue(), file=sys.stderr)
        assert main(["view", "cal", "c", "--html", "v.html"]) == 2
        assert main(["acquire", "acq", "--location", "1", "--arm-port", "x", "--gauge", "x"]) == 2
        for call in (lambda: arm.urdf_robot(), lambda: ap.view("cal", "c", html="w.html")):
            try:
                call()
            except ap.MissingExtraError as exc:
                print(f"raised: {exc}", file=sys.stderr)
    """, tmp_path)
    assert done.returncode == 0, done.stderr
    lines = [ln for ln in done.stderr.splitlines() if "still working" not in ln]
    assert "  figures skipped: the figures extra (matplotlib) is not installed: pip install " \
           '"aacmm_pin[figures]"' in lines
    assert 'aacmm-pin view: error: view needs the viewer extra (meshcat is not installed): pip ' \
           'install "aacmm_pin[viewer]"' in lines
    assert 'aacmm-pin acquire: error: acquire needs the serial extra (pyserial is not installed): ' \
           'pip install "aacmm_pin[serial]"' in lines
    assert 'raised: Arm.urdf_robot needs the urdf extra (yourdfpy is not installed): pip install ' \
           '"aacmm_pin[urdf]"' in lines
    assert any(ln.startswith("raised: view needs the viewer extra") for ln in lines)
    assert "Traceback" not in done.stderr
    assert {p.name for p in (tmp_path / "cal").iterdir()} >= {"parameters.json", "calibrated.urdf"}
    assert (tmp_path / "p.csv").is_file() and (tmp_path / "disc" / "discovery.json").is_file()
    assert not list((tmp_path / "disc").glob("*.png"))
    assert not (tmp_path / "v.html").exists() and not (tmp_path / "w.html").exists()
    assert not (tmp_path / "acq").exists()


def test_missing_extra_error_is_one_line_and_an_import_error():
    """MissingExtraError is an AacmmError and a ModuleNotFoundError naming the module, in one line."""
    from aacmm_pin.errors import AacmmError, MissingExtraError

    exc = MissingExtraError("acquire", "serial", "serial", "pyserial")
    assert isinstance(exc, AacmmError) and isinstance(exc, ModuleNotFoundError)
    assert exc.name == "serial" and "\n" not in str(exc)
    assert str(exc) == 'acquire needs the serial extra (pyserial is not installed): pip install ' \
                       '"aacmm_pin[serial]"'


@pytest.mark.slow
def test_a_fresh_runtime_install_predicts_and_stays_small(tmp_path):
    """`pip install .` in a fresh venv: no extra, import and predict work, the demo skips its
    figures in one line, and the venv stays under 740 MB.

    The ceiling: measured with `du -sm` (Linux x86_64, CPython 3.11.7, pip 23.2, 2026-11), a fresh
    venv took 639 MB with `pip install .` (380 MB of it Pinocchio's wheels), 933 MB with
    `pip install ".[all]"`, as `pip install .` did before the extras (docs/install.md). 740 MB is
    the runtime plus ~100 MB of margin for newer wheels, well below the full install; an extra's
    module slipping back into the runtime is caught directly, by the check that none is importable.
    """
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", str(ROOT)], check=True, timeout=600)
    done = subprocess.run([str(python), "-c", textwrap.dedent("""
        import importlib.util
        import numpy as np
        import aacmm_pin as ap

        arm = ap.load_arm()
        p = ap.predict(arm, ap.Parameters.nominal(arm), np.zeros((2, arm.n_axes)))
        assert p.shape == (2, 3), p.shape
        print([m for m in ("meshcat", "matplotlib", "serial", "yourdfpy", "trimesh", "IPython")
               if importlib.util.find_spec(m) is not None])
    """)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    demo = subprocess.run([str(venv / "bin" / "aacmm-pin"), "demo"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert demo.returncode == 0, demo.stderr
    assert 'figures 5, 6 and 9 skipped: the figures extra (matplotlib) is not installed: pip ' \
           'install "aacmm_pin[figures]"' in demo.stdout
    assert (tmp_path / "aacmm-pin-demo" / "proposed_rtest" / "parameters.json").is_file()
    assert not list((tmp_path / "aacmm-pin-demo").glob("*.png"))
    size_mb = int(subprocess.run(["du", "-sm", str(venv)], capture_output=True, text=True,
                                 check=True).stdout.split()[0])
    assert size_mb < 740, f"{size_mb} MB"
