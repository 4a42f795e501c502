"""What the calibration commands print of a calibration: its summary, the sizes used, the URDF's loss."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aacmm_pin.fit.identification_result import Calibration
    from aacmm_pin.model.arm import Arm


def print_sizes(arm: Arm, indent: str = "") -> None:
    """Print which plausible sizes the arm uses: its sizes file, or the built-in defaults."""
    print(f"{indent}sizes: {arm.sizes_label}")


def print_calibration(cal: Calibration, out: Path) -> None:
    """Print the summary of a calibration: convergence, fit RMS, what is not identifiable."""
    from aacmm_pin.fit.robust import OUTLIER_K

    state = ("converged" if cal.success else "FAILED" if cal.raw.get("success", False)
             else "DID NOT CONVERGE")
    by_loc = ", ".join(f"{cal.group_label(m)}: {v * 1e6:.2f}"
                       for m, v in cal.fit_rms_by_location().items())
    kinds = {"spat": f"SPAT {'with' if cal.use_rtest else 'without'} R-Test",
             "points": "absolute points", "bar": "length bar"}
    data = " + ".join(kinds[k] for k in cal.inputs)
    print(f"{cal.model} model ({data}): {state} ({cal.nfev} evaluations), "
          f"{cal.n_determined} parameters determined, fit RMS {cal.fit_rms * 1e6:.2f} um "
          f"(by {'location' if 'spat' in cal.inputs else 'group'} {by_loc}), "
          f"{cal.runtime_s:.1f} s -> {out}")
    if cal.nests:
        print(f"  R-Test nests {cal.nests}")
    for line in cal.unidentifiable:
        print(f"  not identifiable: {line}")
    for kind, flagged in (("outlier (rejected)", cal.outliers), ("WARNING: suspect", cal.suspects)):
        for o in flagged:
            at = f"line {o.line}" if o.line is not None else f"row {o.row + 1}"
            print(f"  {kind}: {o.file} {at}: residual {o.residual * 1e6:.4g} um "
                  f"({o.sigmas:.3g} sigma)")
    if cal.suspects:
        print(f"  WARNING: {len(cal.suspects)} samples beyond {OUTLIER_K:g} robust sigmas: outliers "
              "or a model that misses an effect; --robust rejects outliers")
    if not cal.success:
        print(f"  {cal.message}")
    elif (note := cal.message.partition("; the residual is ")[2]):  # above the stated noise
        print(f"  NOTE: the residual is {note}")
    print_urdf_loss(out)


def print_urdf_loss(caldir: Path) -> None:
    """Print how far the folder's URDF alone is from the whole calibration (its report's line)."""
    from aacmm_pin.analyses.urdf_loss import loss_line
    from aacmm_pin.outputs.calibration_folder import COMPACT_PARAMETERS_FILE, read_report

    if line := loss_line(read_report(caldir), f"{Path(caldir) / COMPACT_PARAMETERS_FILE}"):
        print(f"  {line}")
