"""Calibrate two real robots from public laser-tracker data: a UR5 and a Barrett WAM.

Data: ``../shared/real-data/jacobi2025-laser-tracker`` (MIT licence; P. Jacobi, *A Hybrid Error
Compensation Method for Enhancing the Pose Accuracy of Serial Industrial Robots*, Master's thesis,
Tsinghua University, 2025; measured with a GTS3800 laser tracker). Each row holds the commanded
joint angles, the commanded (nominal) tool position and its difference from the measured one,
``dif = commanded - measured`` (mm). This script writes them as ``points.csv`` campaigns (absolute
tool points, one instrument frame; what ``aacmm-pin import-points FILE --out FOLDER`` does) and
calibrates the makers' DH models (``urdf/ur5.urdf``,
``urdf/wam7.urdf``, written by ``urdf/make_serial_dh.py``):

* UR5: ``aacmm-pin identify`` on the 1000 grid poses (DH model) and ``aacmm-pin discover`` (what
  the DH model misses, step by step), the DH model, every step's model (refitted on the grid) and
  the final one validated on the 20 random poses never used for calibration (``aacmm-pin
  validate``);
* WAM (grid poses only): ``aacmm-pin discover`` (its k-fold held-out RMS per step), and the DH
  model's and every step's model's mean error on held-out poses by 5-fold cross-validation.

Each robot's plausible sizes (the priors of discovery's held-out scores) are its own,
``urdf/<robot>.sizes.json``. It prints the mean position error uncalibrated and calibrated, beside
the thesis' figures, then the table of docs/real-robots.md: uncalibrated, DH and every discovery step with its
k-fold held-out RMS, fit RMS and test error.

Run: ``python examples/03_laser_tracker_ur5_wam.py [--data DIR] [--out DIR]`` (about 10 s).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import aacmm_pin as ap
from aacmm_pin.analyses.refit_check import refit_error
from aacmm_pin.analyses.validation import validate_points
from aacmm_pin.cli import main
from aacmm_pin.data.point_import import import_points

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker"
PUBLISHED = {"UR5": (2.5664, 0.1549), "WAM": (17.7661, 2.9178)}
"""Thesis: mean absolute position error on its random test poses, mm: uncalibrated, and after
MDH calibration plus a spatio-temporal graph neural network."""
FOLDS = 5


def write_points_campaign(source: Path, folder: Path) -> float:
    """Write the campaign ``folder`` from a tracker CSV (as ``aacmm-pin import-points``).

    Returns its mean uncalibrated error (commanded vs measured point), mm.
    """
    offset = import_points([source], folder).mean_offset
    assert offset is not None  # the jacobi2025 format states the deviations
    return offset * 1e3


@dataclass(frozen=True)
class Row:
    """One model of a robot's table: what it adds and its errors, mm (None: not measured)."""

    model: str
    """``uncalibrated``, ``DH`` or ``+ <effect> on A<n>, ...`` (a discovery step)."""
    heldout_mm: float | None
    """k-fold held-out RMS per coordinate over the grid poses (discovery's score)."""
    fit_mm: float | None
    """Fit RMS per coordinate on the grid poses."""
    test_mm: float | None
    """Mean position error on poses never used for calibration."""


def discover_steps(campaign: Path, arm: str, out: Path) -> list[Row]:
    """Run ``aacmm-pin discover`` from the DH model; return the DH row and one row per step."""
    if main(["discover", str(campaign), "--arm", arm, "--start", "dh", "--out", str(out)]):
        raise SystemExit("discover failed")
    report = json.loads((out / "discovery.json").read_text())
    held, fit = report["gap"]["heldout_rms_um"], report["gap"]["fit_rms_um"]
    names = ["DH"] + [f"+ {s['effect']} on " + ", ".join(sorted(
        (t[t.index("[") + 1:-1] for t in s["terms"]), key=lambda a: (len(a), a)))
        for s in report["steps"]]
    return [Row(n, h / 1e3, f / 1e3, None) for n, h, f in zip(names, held, fit)]


def step_models(out: Path) -> list[tuple[tuple[int, ...], tuple[ap.effects.Term, ...]]]:
    """Return the (map axes, extension terms) of the model after every discovery step."""
    report = json.loads((out / "discovery.json").read_text())
    models, keys = [], []
    for step in report["steps"]:
        keys += step["terms"]
        maps = tuple(int(k[len("encoder_map[A"):-1]) for k in keys if k.startswith("encoder_map["))
        terms = tuple(ap.effects.term_from_key(k) for k in keys if not k.startswith("encoder_map[")
                      and not (k.startswith("encoder_harmonic") and ap.effects.term_from_key(k).axis
                               in maps))
        models.append((maps, terms))
    return models


def ur5(data: Path, out: Path) -> list[Row]:
    """Return the UR5's rows: uncalibrated, DH and every discovery step (20 random test poses)."""
    write_points_campaign(data / "UR5" / "3D_UR5_uncalibrated_grid_cleaned.csv", out / "ur5_grid")
    before = write_points_campaign(data / "UR5" / "3D_UR5_uncalibrated_random_cleaned.csv",
                                   out / "ur5_random")
    status = main(["identify", str(out / "ur5_grid"), "--arm", str(ROOT / "urdf" / "ur5.urdf"),
                   "--model", "dh", "--out", str(out / "ur5_dh")])
    if status:
        raise SystemExit(f"identify did not converge (exit {status})")
    main(["validate", str(out / "ur5_dh"), str(out / "ur5_random"),
          "--json", str(out / "ur5_random_errors.json")])
    after = json.loads((out / "ur5_random_errors.json").read_text())["points"]["mean_mm"]
    rows = discover_steps(out / "ur5_grid", "ur5", out / "ur5_discovered")
    arm = ap.load_arm("ur5")
    grid, test = ap.read_campaign(out / "ur5_grid"), ap.read_campaign(out / "ur5_random")
    tests = [float(after)]
    for maps, terms in step_models(out / "ur5_discovered"):  # each step's model on the test poses
        cal = ap.identify(grid, arm, model="proposed" if maps else "dh", map_axes=maps or None,
                          extensions=terms)
        tests.append(validate_points(arm, cal.parameters, test).mean * 1e3)
    main(["validate", str(out / "ur5_discovered"), str(out / "ur5_random"),
          "--json", str(out / "ur5_random_errors_discovered.json")])
    found = json.loads((out / "ur5_random_errors_discovered.json").read_text())["points"]["mean_mm"]
    tests[-1] = float(found)  # the CLI's final model (a refit of the same model agrees to 0.2 um)
    return [Row("uncalibrated", None, None, before)] + [dataclasses.replace(r, test_mm=t)
                                                         for r, t in zip(rows, tests)]


def kfold_error(campaign: ap.Campaign, arm: ap.Arm, maps: tuple[int, ...] = (),
                terms: tuple[ap.effects.Term, ...] = ()) -> float:
    """Mean position error (mm) of a model on grid poses it was not fitted to.

    The model (``maps``: encoder-map axes, none for DH; ``terms``: extension terms) is fitted
    ``FOLDS`` times, each on all poses but one fold, and predicts the fold it left out
    (:func:`aacmm_pin.analyses.refit_check.refit_error`, discovery's refit check).
    """
    return refit_error(campaign, arm, ap.effects.ModelSpec(terms, maps), folds=FOLDS) * 1e3


def wam(data: Path, out: Path) -> list[Row]:
    """Return the WAM's rows: uncalibrated, DH and every discovery step (test: 5-fold refits)."""
    before = write_points_campaign(data / "WAM" / "3D_WAM_uncalibrated_grid_cleaned.csv",
                                   out / "wam_grid")
    arm = ap.load_arm(ROOT / "urdf" / "wam7.urdf")
    campaign = ap.read_campaign(out / "wam_grid")
    rows = discover_steps(out / "wam_grid", "wam7", out / "wam_discovered")
    models = [((), ()), *step_models(out / "wam_discovered")]  # DH, then each step's model
    rows = [dataclasses.replace(r, test_mm=kfold_error(campaign, arm, *m))
            for r, m in zip(rows, models)]
    return [Row("uncalibrated", None, None, before), *rows]


def run(data: Path, out: Path) -> dict[str, list[Row]]:
    """Calibrate both robots; return robot -> rows (uncalibrated, DH, each discovery step)."""
    return {"UR5": ur5(data, out), "WAM": wam(data, out)}


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def table(results: dict[str, list[Row]]) -> str:
    """Return docs/real-robots.md's table (Markdown) of every robot's models beside the thesis' figures."""
    test = {"UR5": "mean error on the 20 random test poses",
            "WAM": f"mean error: uncalibrated on the grid, every model on {FOLDS}-fold refits"}
    lines = ["| robot | model | k-fold held-out RMS (mm) | fit RMS (mm) | test error (mm) | "
             "thesis: uncalibrated -> MDH + GNN (mm) |", "|---|---|---|---|---|---|"]
    for robot, rows in results.items():
        for i, row in enumerate(rows):
            thesis = (f"{PUBLISHED[robot][0]:.4f} -> {PUBLISHED[robot][1]:.4f}"
                      + ("" if robot == "UR5" else " (its random poses)")) if i == 0 else ""
            lines.append(f"| {robot if i == 0 else ''} | {row.model} | {_mm(row.heldout_mm)} | "
                         f"{_mm(row.fit_mm)} | {_mm(row.test_mm)} | {thesis} |")
    lines.append(f"\nTest error: UR5 {test['UR5']}; WAM {test['WAM']} (no random test file "
                 "is shared for the WAM).")
    return "\n".join(lines)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the jacobi2025 data folder")
    parser.add_argument("--out", type=Path,
                        default=ROOT / "examples" / "out" / "laser-tracker-example",
                        help="folder for the campaigns and calibrations "
                        "(default: examples/out/laser-tracker-example)")
    args = parser.parse_args()
    results = run(args.data, args.out)
    print("\nmean position error (mm)   uncalibrated   DH model   discovered | thesis: uncalibrated"
          "  MDH + GNN")
    for robot, rows in results.items():
        test = "20 random poses" if robot == "UR5" else f"{FOLDS}-fold held-out grid poses"
        found = rows[-1].test_mm if len(rows) > 2 else None  # None: discovery named nothing
        print(f"{robot:<4} ({test:<27}) {_mm(rows[0].test_mm):>8}   {_mm(rows[1].test_mm):>8}   "
              f"{_mm(found):>8}   | {PUBLISHED[robot][0]:>10.4f}  {PUBLISHED[robot][1]:>10.4f}")
    print("\n" + table(results))
