"""The main job, ``aacmm-pin demo``: the paper's experiment on the embedded default arm, simulated.

Simulate a SPAT + length-bar campaign, identify the three models of the paper's Fig. 9 (DH only with
the R-Test; proposed without the R-Test; proposed with the R-Test), validate each on the length bar,
print the table and write the figures (Fig. 5, 6, 9) and the three calibration folders. Without
matplotlib (the ``figures`` extra) it writes all but the figures and says so.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.analyses.validation import ValidationResult, validate
from aacmm_pin.data.campaign import read_campaign
from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.extras import skipped
from aacmm_pin.fit.identification import identify
from aacmm_pin.model.arm import load_arm
from aacmm_pin.outputs.export import write_calibration
from aacmm_pin.outputs.simulation_folder import write_simulation

MODELS = (("dh_rtest", "DH only, R-Test", "dh", True),
          ("proposed_no_rtest", "proposed, no R-Test", "proposed", False),
          ("proposed_rtest", "proposed, R-Test", "proposed", True))
"""(folder, label, model, use_rtest) of the paper's three models."""


def run_demo(out: str | Path = "aacmm-pin-demo", seed: int = 0, force: bool = False
             ) -> dict[str, ValidationResult]:
    """Run the demo, print its table and return each model's validation (keyed by folder name).

    ``out`` is written whole (:func:`~aacmm_pin.data.output_folder.output_folder`): an existing
    folder with files is replaced only with ``force`` (the CLI's ``--force``), as every output.

    Raises:
        OutputExistsError: if ``out`` holds files and not ``force`` (checked before any work).
    """
    tic = time.perf_counter()
    out = Path(out)
    no_figures = skipped("figures", "figures 5, 6 and 9")
    with output_folder(out, force) as tmp:  # claimed now; in place once all is written
        results = _run_demo(out, tmp, seed, figures=no_figures is None)
    if no_figures:
        print(f"{no_figures} ({time.perf_counter() - tic:.0f} s in all)")
    else:
        print(f"figures: {out}/fig5_rtest_displacement.png, fig6_encoder_maps.png, "
              f"fig9_length_errors.png ({time.perf_counter() - tic:.0f} s in all)")
    return results


def _run_demo(out: Path, tmp: Path, seed: int, figures: bool = True) -> dict[str, ValidationResult]:
    """Write the demo's files into ``tmp`` (which becomes ``out``: the paths printed).

    ``figures``: also the PNG files (matplotlib).
    """
    from aacmm_pin.outputs.figure_files import figure_batch
    from aacmm_pin.outputs.plots import plot_encoder_maps, plot_length_errors, plot_rtest_displacement
    from aacmm_pin.progress import phase

    arm = load_arm()
    print(f"aacmm-pin demo: simulating a campaign on the default arm (seed {seed}) ...", flush=True)
    phase("simulating")
    sim = simulate_campaign(arm, SimulationConfig(seed=seed))
    write_simulation(sim, tmp / "campaign")
    campaign = read_campaign(tmp / "campaign")  # what a user has: the files, not the truth
    results: dict[str, ValidationResult] = {}
    calibrations = {}
    for folder, label, model, use_rtest in MODELS:
        print(f"  identifying {label} ...", flush=True)  # a line per step, on a terminal or not
        phase(f"identifying {label}")
        cal = identify(campaign, arm, model=model, use_rtest=use_rtest, progress=True)
        write_calibration(cal, arm, tmp / folder, campaign=campaign)
        results[folder] = validate(arm, cal.parameters, campaign, cal.accuracy)
        calibrations[folder] = cal
        (tmp / folder / "validation.json").write_text(
            json.dumps(results[folder].to_dict(), indent=2) + "\n")
    labels = {folder: label for folder, label, _, _ in MODELS}
    print(_table(results, labels))
    for folder, cal in calibrations.items():
        print(f"  {labels[folder]:<20} fit RMS {cal.fit_rms * 1e6:6.2f} um, "
              f"{cal.n_determined} parameters, {cal.runtime_s:.1f} s, "
              f"{'converged' if cal.success else 'NOT converged'}, nests "
              f"{cal.nests.split(':')[0].replace(' at their measured positions', '')} "
              f"-> {out / folder}")
    if not figures:
        return results
    print("  writing figures 5, 6 and 9 ...", flush=True)
    phase("writing figures")
    best = calibrations["proposed_rtest"]
    with figure_batch():
        plot_rtest_displacement(campaign, tmp / "fig5_rtest_displacement.png")
        plot_encoder_maps({a: best.parameters.map(a).values for a in best.node_identifiable},
                          tmp / "fig6_encoder_maps.png", identifiable=best.node_identifiable,
                          std={a: best.node_std(a) for a in best.node_identifiable},
                          truth=best.maps_in_gauge(sim.truth), reached=best.node_reached)
        plot_length_errors({labels[k]: v for k, v in results.items()},
                           tmp / "fig9_length_errors.png")
    return results


def _table(results: dict[str, ValidationResult], labels: dict[str, str]) -> str:
    """Return the Fig. 9 table: length error per placement and pair, one column per model."""
    keys = list(results)
    first = results[keys[0]]
    cols = [f"{labels[k]:>20}" for k in keys]
    lines = ["Length errors on the bar (um), paper Fig. 9:",
             f"{'placement':>9} {'pair':>5} " + " ".join(cols)]
    for i, placement in enumerate(first.placements):
        for j, (a, b) in enumerate(first.pairs):
            vals = " ".join(f"{results[k].errors[i, j] * 1e6:>20.2f}" for k in keys)
            lines.append(f"{placement:>9} {a + '-' + b:>5} {vals}")
    lines.append(f"{'RMS':>15} " + " ".join(f"{results[k].rms * 1e6:>20.2f}" for k in keys))
    lines.append(f"{'max |error|':>15} " + " ".join(f"{results[k].max_abs * 1e6:>20.2f}"
                                                  for k in keys))
    return "\n".join(lines)
