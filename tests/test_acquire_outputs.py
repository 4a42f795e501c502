"""What ``acquire`` and ``fake-devices`` write besides spat.csv never replaces an input (issue 39).

``acquire --summary FILE`` goes through the guarded writer: refused in one line, before a port is
opened, when FILE is one of the campaign's files (spat.csv, locations.csv), the nest file, or an
existing file without ``--force``. ``fake-devices --json`` may not be its own ``--nest``. The ports
are pyserial's ``loop://`` (silent): the run ends at ``--seconds``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers import run_cli

pytest.importorskip("serial")

PORTS = ["--arm-port", "loop://", *(f"--gauge=heidenhain:{k}=loop://" for k in (1, 2, 3)),
         "--seconds", "0.3", "--quiet", "--location", "1"]
NEST = '{"directions": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}\n'


@pytest.fixture
def campaign(tmp_path: Path) -> Path:
    """A campaign folder with 3,850 recorded rows, its locations and a nest file."""
    folder = tmp_path / "camp"
    folder.mkdir()
    rows = ["location,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg,dx_mm,dy_mm,dz_mm,t_s"]
    rows += [f"1,{k % 90},1,2,3,4,5,6,0.001,0.002,0.003,{k}" for k in range(3850)]
    (folder / "spat.csv").write_text("\n".join(rows) + "\n")
    (folder / "locations.csv").write_text("location,x_mm,y_mm,z_mm\n1,0,0,0\n")
    (tmp_path / "nest.json").write_text(NEST)
    return folder


def _one_error(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("name", ["camp/spat.csv", "camp/locations.csv", "nest.json"])
@pytest.mark.parametrize("force", [False, True])
def test_the_summary_is_never_an_input(campaign, name, force):
    """--summary naming spat.csv, locations.csv or the nest file is refused in one line (exit 2)
    with or without --force; the file keeps every byte (main replaced 3,850 rows by the JSON)."""
    target = campaign.parent / name
    before = target.read_bytes()
    status, err = run_cli(["acquire", str(campaign), *PORTS, "--nest", str(campaign.parent /
                           "nest.json"), "--summary", str(target), *(["--force"] * force)])
    assert status == 2 and str(target) in _one_error(err)
    assert target.read_bytes() == before
    assert not (campaign / "acquire-location1.json").exists()


def test_an_existing_summary_file_is_replaced_only_with_force(campaign):
    """Another existing file as --summary: refused without --force, untouched; replaced with it."""
    mine = campaign.parent / "notes.json"
    mine.write_text('{"mine": 1}\n')
    status, err = run_cli(["acquire", str(campaign), *PORTS, "--summary", str(mine)])
    assert status == 2 and "exists; give --force" in _one_error(err)
    assert mine.read_text() == '{"mine": 1}\n'
    status, err = run_cli(["acquire", str(campaign), *PORTS, "--summary", str(mine), "--force"])
    assert status == 0, err
    assert json.loads(mine.read_text())["rows_written"] == 0


def test_the_default_summary_of_an_earlier_run_is_replaced(campaign):
    """Recording a location again replaces its own default summary (no --force needed), but a
    file of that name that is no summary is refused."""
    for _ in range(2):
        status, err = run_cli(["acquire", str(campaign), *PORTS])
        assert status == 0, err
    assert json.loads((campaign / "acquire-location1.json").read_text())["rows_before"] == 3850
    (campaign / "acquire-location1.json").write_text("my notes\n")
    status, err = run_cli(["acquire", str(campaign), *PORTS])
    assert status == 2 and "acquire-location1.json: exists" in _one_error(err)
    assert (campaign / "acquire-location1.json").read_text() == "my notes\n"


def test_fake_devices_refuse_to_write_their_own_nest_file(tmp_path):
    """fake-devices --nest n.json --json n.json --force: refused in one line, n.json kept."""
    nest = tmp_path / "n.json"
    nest.write_text(NEST)
    status, err = run_cli(["fake-devices", "--nest", str(nest), "--json", str(nest), "--force",
                           "--seconds", "0.1"])
    assert status == 2 and "is an input of this command" in _one_error(err)
    assert nest.read_text() == NEST
