"""A calibration folder with its Monte Carlo uncertainty: ``aacmm-pin uncertainty``'s output.

The calibration's files (:func:`~aacmm_pin.outputs.export.write_calibration_files`), its encoder
maps with each node's Monte Carlo std (``encoder_maps.csv``, ``fig6_encoder_maps.png``) and
``uncertainty.json`` (:func:`~aacmm_pin.analyses.uncertainty.uncertainty_report`), written whole or
not at all.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from aacmm_pin.analyses.uncertainty import MonteCarloResult, uncertainty_report
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.extras import skipped
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.model.arm import Arm
from aacmm_pin.outputs.export import write_calibration_files, write_maps_csv
from aacmm_pin.outputs.plots import plot_encoder_maps


def write_uncertainty(cal: Calibration, arm: Arm, campaign: Campaign, mc: MonteCarloResult,
                      folder: str | Path, force: bool = False) -> str | None:
    """Write the calibration, its maps with their Monte Carlo std and ``uncertainty.json``.

    The folder is written whole (:func:`~aacmm_pin.data.output_folder.output_folder`); the map
    figure only with matplotlib.

    Args:
        cal: the calibration.
        arm: its arm.
        campaign: the campaign it was identified from.
        mc: the Monte Carlo result of ``cal`` on ``campaign``.
        folder: the output folder.
        force: replace a folder that holds files.

    Returns:
        Why the figure was left out (matplotlib missing), or None.

    Raises:
        OutputExistsError: if ``folder`` holds files and not ``force``.
    """
    axes = sorted(cal.node_identifiable)
    nodes = {a: np.degrees(cal.parameters.map(a).nodes) for a in axes}
    std = {a: mc.node_std(a, nodes[a]) for a in axes}
    no_figures = skipped("figures", "fig6_encoder_maps.png") if axes else None
    with output_folder(folder, force) as tmp:  # the folder whole, or not at all
        write_calibration_files(cal, arm, tmp, campaign=campaign)
        write_maps_csv(cal, tmp / "encoder_maps.csv", std=std)
        (tmp / "uncertainty.json").write_text(json.dumps(uncertainty_report(cal, mc), indent=2)
                                              + "\n")
        if axes and not no_figures:
            plot_encoder_maps({a: cal.parameters.map(a).values for a in axes},
                              tmp / "fig6_encoder_maps.png", identifiable=cal.node_identifiable,
                              std=std, reached=cal.node_reached)
    return no_figures
