"""The Barrett WAM's discovered model on poses it was not fitted to, three ways (issue 40).

Run: ``python benchmarks/wam_refits.py`` (about a minute). Data: the WAM grid of
``../shared/real-data/jacobi2025-laser-tracker`` (215 poses), imported as ``aacmm-pin import-points``
does. Prints the mean position error of DH and of the model ``aacmm-pin discover --arm wam7`` ends
with:

* 5-fold refits (:func:`aacmm_pin.analyses.refit_check.refit_error`: folds of shuffled poses, seed
  0, as the README's row; each fold's poses weighted out of the fit, kept in sequence);
* discovery itself inside each of those folds (nested: ``discover`` on the other 4/5, its final
  model predicting the fold; the model's choice is tested too);
* contiguous blocks of the sequence as the 5 folds (each block a region of the grid the others
  may not cover: extrapolation).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import aacmm_pin as ap  # noqa: E402
from aacmm_pin.analyses.refit_check import REFIT_FOLDS, refit_error, weighted_out  # noqa: E402
from aacmm_pin.analyses.validation import validate_points  # noqa: E402
from aacmm_pin.data.point_import import import_points  # noqa: E402
from aacmm_pin.data.poses import pose_folds, pose_ids  # noqa: E402

GRID = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker" / "WAM" / \
    "3D_WAM_uncalibrated_grid_cleaned.csv"


def nested(campaign: ap.Campaign, arm: ap.Arm, folds: list[np.ndarray]) -> tuple[float, float]:
    """Return the mean error (mm) of DH and of default discovery, each fitted without the fold."""
    dh, found = [], []
    for test in folds:
        d = ap.discover(weighted_out(campaign, test), arm, "dh")
        for out, cal in ((dh, d.start_calibration), (found, d.calibration)):
            errors = validate_points(arm, cal.parameters, campaign).errors[test]
            out.append(np.linalg.norm(errors, axis=1))
        print(f"  fold of {len(test)} poses: named {[f'{s.effect} {s.axes}' for s in d.steps]}, "
              f"DH {dh[-1].mean() * 1e3:.4f} mm, discovered {found[-1].mean() * 1e3:.4f} mm")
    return float(np.mean(np.concatenate(dh)) * 1e3), float(np.mean(np.concatenate(found)) * 1e3)


def main() -> None:
    """Print the three tests' mean errors of DH and the discovered model."""
    arm = ap.load_arm("wam7")
    with tempfile.TemporaryDirectory() as tmp:
        import_points([GRID], Path(tmp) / "grid")
        campaign = ap.read_campaign(Path(tmp) / "grid")
    final = ap.discover(campaign, arm, "dh").calibration
    model = ap.effects.ModelSpec(tuple(ap.effects.term_from_key(k)
                                       for k in sorted(final.parameters.extensions)),
                                 tuple(final.unknowns.map_axes))
    print(f"discovered model: {', '.join(t.key for t in model.terms)}")
    assert campaign.points is not None
    shuffled = pose_folds(pose_ids(campaign.points.q), REFIT_FOLDS)
    blocks = np.array_split(np.arange(len(campaign.points.q)), REFIT_FOLDS)
    for name, rows in ((f"{REFIT_FOLDS}-fold refits", shuffled), ("contiguous blocks", blocks)):
        dh, found = (refit_error(campaign, arm, m, fold_rows=rows) * 1e3
                     for m in (ap.effects.ModelSpec(), model))
        print(f"{name}: DH {dh:.4f} mm, discovered {found:.4f} mm")
    print("discover inside each of the 5 folds:")
    dh, found = nested(campaign, arm, shuffled)
    print(f"nested: DH {dh:.4f} mm, discovered {found:.4f} mm")


if __name__ == "__main__":
    main()
