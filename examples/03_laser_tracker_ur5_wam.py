"""Calibrate two real robots from public laser-tracker data: a UR5 and a Barrett WAM.

Data: ``../shared/real-data/jacobi2025-laser-tracker`` (MIT licence; P. Jacobi, *A Hybrid Error
Compensation Method for Enhancing the Pose Accuracy of Serial Industrial Robots*, Master's thesis,
Tsinghua University, 2025; measured with a GTS3800 laser tracker). Each row holds the commanded
joint angles, the commanded (nominal) tool position and its difference from the measured one,
``dif = commanded - measured`` (mm). This script writes them as ``points.csv`` campaigns (absolute
tool points, one instrument frame) and calibrates the makers' DH models (``urdf/ur5.urdf``,
``urdf/wam7.urdf``, written by ``urdf/make_serial_dh.py``):

* UR5: ``aacmm-pin identify`` on the 1000 grid poses (DH model) and ``aacmm-pin discover`` (what
  the DH model misses, step by step), each validated by ``aacmm-pin validate`` on the 20 random
  poses never used for calibration;
* WAM (grid poses only): the DH model's error on held-out poses by 5-fold cross-validation, and
  ``aacmm-pin discover`` (its k-fold held-out RMS per step).

It prints the mean position error uncalibrated and calibrated, beside the thesis' figures, and the
discovery steps.

Run: ``python examples/03_laser_tracker_ur5_wam.py [--data DIR] [--out DIR]`` (a few seconds).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
from pathlib import Path

import numpy as np

import aacmm_pin as ap
from aacmm_pin.cli import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker"
PUBLISHED = {"UR5": (2.5664, 0.1549), "WAM": (17.7661, 2.9178)}
"""Thesis: mean absolute position error on its random test poses, mm: uncalibrated, and after
MDH calibration plus a spatio-temporal graph neural network."""
FOLDS = 5


def write_points_campaign(source: Path, folder: Path) -> float:
    """Write ``folder/points.csv`` from a tracker CSV; return its mean uncalibrated error, mm."""
    with source.open(newline="") as f:
        rows = list(csv.DictReader(f))
    n = sum(1 for key in rows[0] if key.startswith("joint_"))
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "points.csv").open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow([f"q{i}_deg" for i in range(1, n + 1)] + ["x_mm", "y_mm", "z_mm"])
        for r in rows:  # measured = commanded - dif
            out.writerow([r[f"joint_{i}"] for i in range(1, n + 1)]
                         + [float(r[f"{c}_t"]) - float(r[f"{c}_dif"]) for c in "xyz"])
    dif = np.array([[float(r[f"{c}_dif"]) for c in "xyz"] for r in rows])
    return float(np.mean(np.linalg.norm(dif, axis=1)))


def discover_steps(campaign: Path, arm: str, out: Path) -> list[str]:
    """Run ``aacmm-pin discover`` from the DH model; return one line per step (k-fold held out)."""
    if main(["discover", str(campaign), "--arm", arm, "--start", "dh", "--out", str(out)]):
        raise SystemExit("discover failed")
    report = json.loads((out / "discovery.json").read_text())
    return [f"{s['effect']} on A{', A'.join(str(a) for a in s['axes'])}: k-fold held-out RMS "
            f"{s['heldout_rms_before_um'] / 1e3:.4f} -> {s['heldout_rms_after_um'] / 1e3:.4f} mm"
            for s in report["steps"]]


def ur5(data: Path, out: Path) -> tuple[float, float, float, list[str]]:
    """Return the UR5's mean error on the random poses, mm: uncalibrated, DH, discovered model."""
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
    steps = discover_steps(out / "ur5_grid", "ur5", out / "ur5_discovered")
    main(["validate", str(out / "ur5_discovered"), str(out / "ur5_random"),
          "--json", str(out / "ur5_random_errors_discovered.json")])
    found = json.loads((out / "ur5_random_errors_discovered.json").read_text())["points"]["mean_mm"]
    return before, float(after), float(found), steps


def wam(data: Path, out: Path) -> tuple[float, float, float, list[str]]:
    """Return the WAM's mean error, mm: uncalibrated, and DH-calibrated on held-out folds."""
    before = write_points_campaign(data / "WAM" / "3D_WAM_uncalibrated_grid_cleaned.csv",
                                   out / "wam_grid")
    arm = ap.load_arm(ROOT / "urdf" / "wam7.urdf")
    campaign = ap.read_campaign(out / "wam_grid")
    points = campaign.points
    assert points is not None
    order = np.random.default_rng(0).permutation(len(points.q))
    errors = []
    for test in np.array_split(order, FOLDS):
        train = np.setdiff1d(order, test)
        part = dataclasses.replace(points, group=points.group[train], q=points.q[train],
                                   point=points.point[train], lines=None)
        cal = ap.identify(dataclasses.replace(campaign, points=part), arm, model="dh")
        pred = ap.stylus_positions(arm, cal.parameters, points.q[test], frame="mt")
        errors.append(np.linalg.norm(pred - points.point[test], axis=1))
    steps = discover_steps(out / "wam_grid", "wam7", out / "wam_discovered")
    return before, float(np.mean(np.concatenate(errors)) * 1e3), float("nan"), steps


def run(data: Path, out: Path) -> dict[str, tuple[float, float, float, list[str]]]:
    """Calibrate both robots; return robot -> (uncalibrated, DH, discovered) mean error, mm, and
    the discovery steps (the WAM's discovered model has no test poses: NaN)."""
    return {"UR5": ur5(data, out), "WAM": wam(data, out)}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the jacobi2025 data folder")
    parser.add_argument("--out", type=Path, default=Path("laser-tracker-example"),
                        help="folder for the campaigns and calibrations")
    args = parser.parse_args()
    results = run(args.data, args.out)
    print("\nmean position error (mm)   uncalibrated   DH model   discovered | thesis: uncalibrated"
          "  MDH + GNN")
    for robot, (before, after, found, _) in results.items():
        test = "20 random poses" if robot == "UR5" else f"{FOLDS}-fold held-out grid poses"
        print(f"{robot:<4} ({test:<27}) {before:>8.4f}   {after:>8.4f}   {found:>8.4f}   | "
              f"{PUBLISHED[robot][0]:>10.4f}  {PUBLISHED[robot][1]:>10.4f}")
    for robot, (*_, steps) in results.items():
        print(f"{robot} discovery from the DH model:", *(f"\n  step {k}: {s}"
                                                       for k, s in enumerate(steps, 1)) or " none")
