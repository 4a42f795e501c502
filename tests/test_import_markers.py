"""import-points on a motion-capture export: two markers per pose (tool and pose columns), the
joints named as the arm names them, a coupled joint without a column, a relative provenance."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.cli import main
from aacmm_pin.data.point_import import PointFormat, import_points
from aacmm_pin.model.kinematics import stylus_positions

TORSO = Path(__file__).resolve().parents[1] / "urdf" / "torso_coupled.urdf"
POSES = 150
SIGMA = 20e-6


@pytest.fixture(scope="module")
def torso() -> ap.Arm:
    return ap.load_arm(str(TORSO))


def write_export(arm: ap.Arm, path: Path, seed: int = 0) -> dict[str, np.ndarray]:
    """Write a motion-capture export: frame, marker, the independent joints (deg, named as the arm
    names them, T4 left out), X, Y, Z (mm) of both markers of every pose; return the truth."""
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(seed=seed, points=POSES, effects=("dh",)))
    points = sim.campaign.points
    assert points is not None
    q = np.repeat(points.q, 2, axis=0)
    tool = np.tile(np.array(arm.tool_names), POSES)
    truth = sim.truth
    exact = stylus_positions(arm, truth, q, "mt", tool=tool)
    measured = exact + np.random.default_rng(seed).normal(0.0, SIGMA, exact.shape)
    free = [k for k in range(arm.n_axes) if not arm.coupled[k]]
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["frame", "marker", *(arm.axis_names[k] for k in free), "X", "Y", "Z"])
        for i in range(len(q)):
            out.writerow([f"f{i // 2:04d}", tool[i], *(f"{v:.9f}" for v in np.degrees(q[i, free])),
                          *(f"{v:.6f}" for v in measured[i] * 1e3)])
    return {"q": q, "tool": tool}


def test_two_marker_export_becomes_a_campaign_identify_accepts(torso: ap.Arm, tmp_path: Path) -> None:
    """The export read with --arm, --tool, --pose: points.csv has T1_deg.. (no T4_deg, no q<k>_deg),
    tool left/right, one pose number per frame; campaign.json names the source relative to the
    campaign; identify reads it unchanged and fits it to the markers' noise."""
    src = tmp_path / "data" / "mocap.csv"
    src.parent.mkdir()
    truth = write_export(torso, src)
    assert main(["import-points", str(src), "--arm", str(TORSO), "--point", "X,Y,Z", "--tool",
                 "marker", "--pose", "frame", "--sigma-um", "20", "--out",
                 str(tmp_path / "campaign")]) == 0
    with (tmp_path / "campaign" / "points.csv").open() as f:
        rows = list(csv.DictReader(f))
    header = list(rows[0])
    assert "T1_deg" in header and "R7_deg" in header
    assert "T4_deg" not in header and not any(h.startswith("q") for h in header)
    assert [r["tool"] for r in rows] == list(truth["tool"])
    assert [int(float(r["pose"])) for r in rows] == list(np.repeat(np.arange(1, POSES + 1), 2))
    provenance = json.loads((tmp_path / "campaign" / "campaign.json").read_text())["provenance"]
    assert provenance["files"][0]["file"] == "../data/mocap.csv"
    campaign = ap.read_campaign(tmp_path / "campaign", arm=torso)
    assert campaign.points is not None
    np.testing.assert_allclose(campaign.points.q, truth["q"], atol=1e-9)  # T4 from its coupling
    assert main(["identify", str(tmp_path / "campaign"), "--arm", str(TORSO), "--model", "dh",
                 "--out", str(tmp_path / "cal")]) == 0
    report = json.loads((tmp_path / "cal" / "report.json").read_text())
    assert report["success"]
    assert report["fit_rms_um"] < 1.2 * SIGMA * 1e6  # the markers' noise, less the fit's dof


def test_import_refuses_an_unknown_marker_and_a_misnumbered_joint_list(torso: ap.Arm,
                                                                         tmp_path: Path) -> None:
    """A marker the arm has no tool for is one problem naming file, line and column; joint
    columns that are neither the independent axes nor all axes are refused naming the axes."""
    src = tmp_path / "mocap.csv"
    write_export(torso, src)
    text = src.read_text().splitlines()
    text[3] = text[3].replace(",left,", ",lfet,").replace(",right,", ",lfet,")
    src.write_text("\n".join(text) + "\n")
    free = tuple(torso.axis_names[k] for k in range(torso.n_axes) if not torso.coupled[k])
    fmt = PointFormat(free, (("X", None), ("Y", None), ("Z", None)), tool="marker", pose="frame")
    with pytest.raises(ap.AacmmError, match=r"mocap.csv:4: column 'marker': unknown tool 'lfet' "
                                            r"\(1 rows\); did you mean left\?"):
        import_points([src], tmp_path / "out", fmt, arm=torso)
    short = PointFormat(free[:-1], fmt.point, tool="marker")
    with pytest.raises(ValueError, match="16 joint columns for the arm's 17 independent axes"):
        import_points([src], tmp_path / "out2", short, arm=torso)


def test_a_coupled_joints_column_is_checked_not_dropped(torso: ap.Arm, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """Every joint given, the coupled T4 among them: kept if it follows its coupling, else refused
    in one line naming the joint, the row and the coupling (it was dropped without a check)."""
    src = tmp_path / "mocap.csv"
    write_export(torso, src)
    rows = list(csv.reader(src.open()))
    header, body = rows[0], rows[1:]
    names = torso.axis_names
    t2, t3 = header.index("T2"), header.index("T3")
    for wrong in (False, True):
        out = [header[:4] + ["T4"] + header[4:]]
        for r in body:
            t4 = 55.0 if wrong else -(float(r[t2]) + float(r[t3]))
            out.append(r[:4] + [f"{t4:.9f}"] + r[4:])
        path = tmp_path / f"all{int(wrong)}.csv"
        with path.open("w", newline="") as f:
            csv.writer(f).writerows(out)
        assert names.index("T4") == 3
        code = main(["import-points", str(path), "--arm", str(TORSO), "--point", "X,Y,Z",
                     "--joints", ",".join(names), "--tool", "marker", "--pose", "frame",
                     "--out", str(tmp_path / f"c{int(wrong)}")])
        err = capsys.readouterr().err.strip().splitlines()
        if not wrong:
            assert code == 0, err
            continue
        assert code == 2 and len(err) == 1, err
        assert "coupled joint T4" in err[0] and "data row 1" in err[0] and "T4 = -T2 - T3" in err[0]
