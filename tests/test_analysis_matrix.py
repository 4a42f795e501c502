"""Every analysis on every kind of campaign the reader accepts: it works, or refuses in one line.

Kinds: SPAT only, SPAT + length bar, absolute points (one instrument frame), point groups (two
instrument frames), a tree (two tools) and SPAT + points (their own tracker frame) + bar. Analyses:
``uncertainty``, ``plan``, ``discover``, ``validate``, ``view``, ``iso10360 spat`` / ``euni``, each
run as a user runs it (the CLI, in-process). The campaigns are tiny (tens of samples): these check
that nothing crashes and that the numbers are those of what was fitted, not the statistics.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import Campaign, PointLog
from aacmm_pin.units import SIGMA_POINT

ROOT = Path(__file__).resolve().parents[1]
TORSO = ROOT / "urdf" / "torso.urdf"
KINDS = ("spat", "bar", "points", "groups", "tree", "mixed")
ONE_LINE = re.compile(r"aacmm-pin [a-z0-9 ]+: error: [^\n]+\n")


def _rotated(points: np.ndarray, angle: float, shift: list[float]) -> np.ndarray:
    """Points in another instrument frame: turned about z by ``angle`` rad and shifted, m."""
    c, s = math.cos(angle), math.sin(angle)
    return points @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T + shift


def _poses(arm: ap.Arm, n: int, rng: np.random.Generator) -> np.ndarray:
    lim = arm.joint_limits
    q: np.ndarray = rng.uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))
    return q


def _write_campaigns(folder: Path) -> dict[str, Path]:
    """Write one tiny campaign of every kind below ``folder``; return kind -> campaign folder."""
    arm = ap.load_arm()
    rng = np.random.default_rng(1)
    sim = simulate_campaign(arm, SimulationConfig(samples_per_location=20, samples_per_socket=5,
                                                  bar_placements=2))
    c = sim.campaign
    q = _poses(arm, 40, rng)
    tracker = _rotated(ap.stylus_positions(arm, sim.truth, q, frame="mt")
                       + rng.normal(0.0, SIGMA_POINT, (40, 3)), 0.3, [1.0, 0.5, 0.2])
    points = simulate_campaign(arm, SimulationConfig(points=40)).campaign
    assert points.points is not None
    pts = points.points
    second = np.arange(40) >= 20  # the second half measured from another tracker station
    moved = np.where(second[:, None], _rotated(pts.point, -0.4, [0.3, -0.2, 0.1]), pts.point)
    torso = ap.load_arm(TORSO)
    campaigns = {
        "spat": Campaign(spat=c.spat, locations=c.locations, lengthbar=None, bar={}),
        "bar": c,
        "points": points,
        "groups": Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
            group=np.where(second, 2, 1), q=pts.q, point=moved)),
        "tree": simulate_campaign(torso, SimulationConfig(points=60, effects=("dh",))).campaign,
        "mixed": Campaign(spat=c.spat, locations=c.locations, lengthbar=c.lengthbar, bar=c.bar,
                          points=PointLog(group=np.ones(40, dtype=np.int64), q=q, point=tracker)),
    }
    out = {}
    for kind, campaign in campaigns.items():
        out[kind] = folder / kind
        out[kind].mkdir()
        ap.write_campaign(campaign, out[kind])
    return out


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return _write_campaigns(tmp_path_factory.mktemp("campaigns"))


def _arm(kind: str) -> list[str]:
    return ["--arm", str(TORSO)] if kind == "tree" else []


@pytest.fixture(scope="module")
def calibrations(campaigns: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
                 ) -> dict[str, Path]:
    """A dh calibration of every campaign (identify --model dh), kind -> CALDIR."""
    folder = tmp_path_factory.mktemp("calibrations")
    out = {}
    for kind, campaign in campaigns.items():
        out[kind] = folder / kind
        assert main(["identify", str(campaign), *_arm(kind), "--model", "dh",
                     "--out", str(out[kind])]) == 0
    return out


def _run(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str]:
    """Run the CLI in-process; return its status, stdout and stderr (a traceback fails the test)."""
    status = main(argv)
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def _refused_in_one_line(status: int, err: str, *words: str) -> None:
    """A refusal: status 2, one line on stderr saying why (``words`` in it), no traceback."""
    assert status == 2, err
    assert ONE_LINE.fullmatch(err), err
    assert all(w in err for w in words), err


def _finite(values: list[float]) -> bool:
    return bool(np.all(np.isfinite(np.asarray(values, dtype=float))))


@pytest.mark.parametrize("kind", KINDS)
def test_uncertainty(kind, campaigns, tmp_path, capsys):
    """uncertainty works on every kind: every identifiable entry gets a finite, positive MC std."""
    out = tmp_path / "u"
    status, text, err = _run(capsys, ["uncertainty", str(campaigns[kind]), *_arm(kind),
                                      "--model", "dh", "--trials", "3", "--workers", "1",
                                      "--out", str(out)])
    assert status == 0, err
    report = json.loads((out / "uncertainty.json").read_text())
    assert report["converged"] == 3
    stds = [p["std_mc"] for p in report["parameters"].values() if p["identifiable"]]
    assert len(stds) > 10 and _finite(stds) and min(stds) > 0
    assert ("points by their stated noise" in text) == (kind not in ("spat", "bar"))


@pytest.mark.parametrize("kind", KINDS)
def test_plan(kind, campaigns, tmp_path, capsys):
    """plan ranks candidates for campaigns with SPATs, refuses the others in one line."""
    out = tmp_path / "plan.json"
    argv = ["plan", str(campaigns[kind]), *_arm(kind), "--postures", "5", "--grid", "1",
            "--heights-mm", "0", "--top", "2", "--json", str(out)]
    status, text, err = _run(capsys, argv)
    if kind in ("points", "groups", "tree"):
        _refused_in_one_line(status, err, "no SPAT", "points")
        assert not out.exists()
        return
    assert status == 0, err
    result = json.loads(out.read_text())
    assert result["candidates"] and _finite(list(result["map_std_arcsec"].values()))
    assert result["points_left_out"] == (40 if kind == "mixed" else 0)
    assert ("not counted" in text) == (kind == "mixed")


@pytest.mark.parametrize("kind", KINDS)
def test_discover(kind, campaigns, tmp_path, capsys):
    """discover works on every kind: a finite held-out RMS, discovery.json written."""
    out = tmp_path / "d"
    status, text, err = _run(capsys, ["discover", str(campaigns[kind]), *_arm(kind), "--start",
                                      "dh", "--max-steps", "1", "--out", str(out)])
    assert status == 0, err
    held = re.search(r"start dh: held-out RMS ([0-9.]+) um", text)
    assert held and 0 < float(held.group(1)) < 1e3, text  # um: a calibrated arm, not a failure
    assert (out / "discovery.json").is_file()


@pytest.mark.parametrize("kind", KINDS)
def test_view_shows_the_residual_that_was_fitted(kind, campaigns, calibrations, tmp_path, capsys):
    """view's RMS is the calibration's fit RMS (report.json) on its own campaign, points included."""
    html = tmp_path / "v.html"
    status, text, err = _run(capsys, ["view", str(calibrations[kind]), str(campaigns[kind]),
                                      "--html", str(html)])
    assert status == 0, err
    shown = float(re.search(r"RMS ([0-9.]+) um", text).group(1))  # type: ignore[union-attr]
    fitted = json.loads((calibrations[kind] / "report.json").read_text())["fit_rms_um"]
    assert shown == pytest.approx(fitted, abs=0.006) and shown > 0  # printed with 2 decimals
    assert html.stat().st_size > 0


@pytest.mark.parametrize("kind", KINDS)
def test_validate(kind, campaigns, calibrations, tmp_path, capsys):
    """validate on the bar and on points (every instrument frame), or one line without either."""
    out = tmp_path / "v.json"
    status, text, err = _run(capsys, ["validate", str(calibrations[kind]), str(campaigns[kind]),
                                      "--json", str(out)])
    if kind == "spat":
        _refused_in_one_line(status, err, "no length-bar data")
        return
    assert status == 0, err
    data = json.loads(out.read_text())
    if kind in ("bar", "mixed"):
        assert _finite([data["rms_um"], data["max_abs_um"]])
    if kind != "bar":
        # the fitted campaign itself: each 3-D error is ~ sqrt(3) x the per-coordinate noise
        # (20 um) plus what a dh model leaves (a few tens of um); a frame taken for the
        # calibration's when it is another instrument's is off by metres
        assert data["points"]["rms_mm"] < 10 * math.sqrt(3) * SIGMA_POINT * 1e3, text
        assert data["points"]["fitted_frame_groups"] == {"groups": [2], "mixed": [1]}.get(kind, [])


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("figure", ["spat", "euni"])
def test_iso10360(figure, kind, campaigns, calibrations, capsys):
    """iso10360 spat / euni where the campaign has SPATs / a bar, else one line saying it lacks it."""
    status, text, err = _run(capsys, ["iso10360", figure, str(campaigns[kind]), *_arm(kind),
                                      "--params", str(calibrations[kind])])
    has = {"spat": kind in ("spat", "bar", "mixed"), "euni": kind in ("bar", "mixed")}[figure]
    if not has:
        _refused_in_one_line(status, err, "no SPAT" if figure == "spat" else "no length-bar")
        return
    assert status == 0, err
    numbers = [float(v) for v in re.findall(r"\d+\.\d+", text)]
    assert numbers and _finite(numbers)
