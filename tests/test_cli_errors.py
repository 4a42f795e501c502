"""The command line's rough edges (issue 26, item 9): stray arguments, wrong paths.

* A stray argument is reported with the usage of the subcommand it was given to, not the list of
  commands (``aacmm-pin iso10360 euni CALDIR CAMPAIGN``: the calibration goes with ``--params``).
* A path that does not exist is reported before the command imports numpy, Pinocchio or SciPy
  (the check is on what was imported, not on a time: the machine's load does not enter).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.helpers import ENV, run_cli
from tests.test_cli import HEAVY


@pytest.mark.parametrize("argv", [["iso10360", "euni", "cal", "campaign"],
                                  ["identify", "campaign", "extra"],
                                  ["validate", "cal", "campaign", "--no-such-option"]],
                         ids=" ".join)
def test_stray_argument_is_reported_by_its_subcommand(argv: list[str], capsys) -> None:
    status, err = run_cli(argv)
    command = " ".join(argv[:2] if argv[0] == "iso10360" else argv[:1])
    assert status == 2
    assert err.splitlines()[0].startswith(f"usage: aacmm-pin {command} "), err
    assert err.splitlines()[-1].startswith(f"aacmm-pin {command}: error: unrecognized arguments")


MISSING = "no/such/path"
WRONG_PATHS = [
    ["identify", MISSING], ["discover", MISSING], ["uncertainty", MISSING], ["plan", MISSING],
    ["validate", MISSING, MISSING], ["predict", MISSING, MISSING], ["view", MISSING, MISSING],
    ["iso10360", "spat", MISSING], ["iso10360", "euni", MISSING],
    ["iso10360", "sphere", MISSING, "--diameter-mm", "25"], ["iso10360", "ldia", MISSING],
    ["identify", "--effects-file", MISSING, "."], ["iso10360", "euni", "--params", MISSING, "."],
    ["identify", ".", "--arm", f"{MISSING}.urdf"], ["axes", f"{MISSING}.urdf"],
    ["simulate", "out", "--arm", MISSING],
]


def test_wrong_path_is_reported_before_any_heavy_import(tmp_path) -> None:
    """Every command with a missing input: exit 2, one line naming the path, nothing heavy loaded."""
    code = (
        "import contextlib, io, json, sys\n"
        "from aacmm_pin.cli import main\n"
        "out = []\n"
        f"for argv in {WRONG_PATHS!r}:\n"
        "    err = io.StringIO()\n"
        "    with contextlib.redirect_stderr(err):\n"
        "        status = main(argv)\n"
        "    out.append([argv, status, err.getvalue()])\n"
        "print(json.dumps([out, sorted(m.split('.')[0] for m in sys.modules)]))\n")
    text = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV,
                          cwd=tmp_path, check=True, timeout=120).stdout
    results, modules = json.loads(text)
    for argv, status, err in results:
        assert status == 2, argv
        assert len(err.splitlines()) == 1 and MISSING in err, (argv, err)
    assert [m for m in HEAVY if m in modules] == []
