"""What ``aacmm-pin identify`` imports: its floor (numpy, scipy's solver, Pinocchio, lxml) and the
standard library, nothing else (issue 41: imports were 82 % of its CPU on a paper-sized campaign).

A module added to the identify path that its work does not need (``scipy.stats``: 0.3 s of CPU,
matplotlib, meshcat, a figure or viewer module, the discovery scorer) fails here with its name.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import aacmm_pin as ap
from tests.helpers import ENV

FLOOR = ("numpy", "scipy.linalg", "scipy.optimize", "scipy.sparse.linalg", "scipy.special",
         "pinocchio", "lxml.etree", "threadpoolctl")
"""What an identification cannot avoid importing: the arrays, the solver and its sparse
operators, the two special functions of the noise tests, the kinematics, the URDF tree, the BLAS
thread limit."""
NOT_FOR_IDENTIFY = ("aacmm_pin.outputs.plots", "aacmm_pin.outputs.figure_files",
                    "aacmm_pin.outputs.discovery_figures", "aacmm_pin.outputs.viewer",
                    "aacmm_pin.outputs._viewer_scene", "aacmm_pin.acquire",
                    "aacmm_pin.analyses.linear_scorer", "aacmm_pin.analyses.validation",
                    "aacmm_pin.analyses.discovery", "aacmm_pin.analyses.residual_scan",
                    "aacmm_pin.analyses.simulate")
"""The package's modules an ``identify`` of a SPAT campaign never runs."""

MODULES = "import json, sys; print(json.dumps(sorted(sys.modules)))"


def _modules(code: str, cwd: Path) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV,
                         cwd=cwd, check=True, timeout=300).stdout
    return set(json.loads(out.strip().splitlines()[-1]))


def test_identify_imports_its_floor_and_the_standard_library_only(tmp_path: Path,
                                                                  small_sim: ap.Simulation
                                                                  ) -> None:
    ap.write_simulation(small_sim, tmp_path / "c")
    floor = _modules(f"import {', '.join(FLOOR)}; {MODULES}", tmp_path)
    run = ("import contextlib, io\nfrom aacmm_pin.cli import main\n"
           "with contextlib.redirect_stdout(io.StringIO()):\n"
           "    assert main(['identify', 'c', '--model', 'proposed', '--out', 'cal']) == 0\n"
           f"{MODULES}\n")
    used = _modules(run, tmp_path)
    assert "pinocchio" in used and "scipy.optimize" in used  # it did the work
    extra = sorted(m for m in used - floor if not m.startswith("aacmm_pin")
                   and m.split(".")[0] not in sys.stdlib_module_names)
    assert extra == [], ("identify imports more than its floor: "
                         f"{sorted({'.'.join(m.split('.')[:2]) for m in extra})}")
    assert sorted(m for m in used if m.startswith(NOT_FOR_IDENTIFY)) == []
    for heavy in ("scipy.stats", "scipy.interpolate", "scipy.ndimage", "matplotlib", "meshcat",
                  "serial", "yourdfpy", "trimesh", "tqdm"):
        assert heavy not in used


def test_identify_started_by_the_command_line_leaves_threadpoolctl_unloaded(tmp_path: Path,
                                                                           small_sim: ap.Simulation
                                                                           ) -> None:
    """The command line starts BLAS with one thread before numpy loads; with the wheels' OpenBLAS
    (which reads that variable) identify's BLAS limit then has nothing to do and does not load
    threadpoolctl (which reads every loaded library's path:
    ~20 ms of each command). The BLAS libraries run one thread each all the same."""
    ap.write_simulation(small_sim, tmp_path / "c")
    env = {k: v for k, v in ENV.items() if not k.endswith("_NUM_THREADS")}
    run = ("import contextlib, io, json, sys\nfrom aacmm_pin.cli import main\n"
           "with contextlib.redirect_stdout(io.StringIO()):\n"
           "    assert main(['identify', 'c', '--model', 'proposed', '--out', 'cal']) == 0\n"
           "loaded = 'threadpoolctl' in sys.modules\n"
           "from aacmm_pin._blas import _threads_from_environment\n"
           "wheels = _threads_from_environment()\n"
           "from threadpoolctl import threadpool_info\n"
           "print(json.dumps([loaded, wheels, sorted({i['num_threads'] for i in threadpool_info()\n"
           "                                  if i['user_api'] == 'blas'})]))\n")
    out = subprocess.run([sys.executable, "-c", run], capture_output=True, text=True, env=env,
                         cwd=tmp_path, check=True, timeout=300).stdout
    loaded, wheels, threads = json.loads(out.strip().splitlines()[-1])
    assert loaded is not wheels  # the wheels' OpenBLAS reads the variable; other builds get the limit
    assert threads == [1]


def test_predict_and_the_runtime_object_import_no_scipy(tmp_path: Path, arm: ap.Arm,
                                                       small_sim: ap.Simulation) -> None:
    """Reading a calibration and moving its arm needs arrays, Pinocchio and the URDF tree only:
    `predict` and `load_calibrated` (what a robotics stack imports) load no SciPy (~0.6 s of
    CPU of each process that did: `predict` 1.9 -> 0.9 s as a whole process)."""
    ap.write_simulation(small_sim, tmp_path / "c")
    cal = ap.identify(small_sim.campaign, arm, model="proposed")
    ap.write_calibration(cal, arm, tmp_path / "cal")
    run = ("import contextlib, io\nfrom aacmm_pin.cli import main\n"
           "with contextlib.redirect_stdout(io.StringIO()):\n"
           "    assert main(['predict', 'cal', 'c/spat.csv', '--out', 'p.csv']) == 0\n"
           f"{MODULES}\n")
    runtime = ("import numpy as np\nimport aacmm_pin as ap\nrt = ap.load_calibrated('cal')\n"
               "rt.position(np.zeros(rt.n_axes)); rt.jacobian(np.zeros(rt.n_axes))\n"
               f"rt.readouts(np.zeros(rt.n_axes))\n{MODULES}\n")
    for code in (run, runtime):
        used = _modules(code, tmp_path)
        assert "pinocchio" in used  # it did the work
        assert sorted(m for m in used if m.split(".")[0] == "scipy") == []
        assert sorted(m for m in used if m.startswith("aacmm_pin.fit")) == []
