"""A calibration folder (CALDIR): parameters, calibrated URDF, maps CSV and report.

``CALDIR/parameters.json`` names ``calibrated.urdf`` beside it, so the folder is self-contained;
``calibrated.urdf`` holds the identified DH values in its error frames and the identified tool vector
of every tool (it carries no maps: wrap readouts with ``encoder_maps.csv`` / ``parameters.json``
maps first); ``calibrated.sizes.json`` beside it carries the arm's plausible sizes, if it has any.
:func:`read_calibration` (:mod:`aacmm_pin.outputs.calibration_folder`, which needs no identification)
reads a folder back.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.effects.registry import write_parameters
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.sizes import sizes_path, write_sizes
from aacmm_pin.outputs.calibration_folder import (
    MAPS_FILE,
    PARAMETERS_FILE,
    REPORT_FILE,
    URDF_FILE,
    CalibrationFolder,
    read_calibration,
)
from aacmm_pin.outputs.instrument_frames import FRAMES_KEY, instrument_frames
from aacmm_pin.outputs.urdf_resources import rebase_resources
from aacmm_pin.units import ARCSEC

__all__ = ["CalibrationFolder", "read_calibration", "write_calibration", "write_calibration_files",
           "write_maps_csv"]


def write_maps_csv(cal: Calibration, path: str | Path, std: dict[int, np.ndarray] | None = None
                   ) -> None:
    """Write ``axis,node_deg,error_arcsec,identifiable,std_arcsec`` for every estimated map.

    Args:
        cal: the calibration.
        path: CSV to write.
        std: axis -> node standard uncertainty (rad) to write instead of the linearised one
            (e.g. from Monte Carlo).
    """
    rows = ["axis,node_deg,error_arcsec,identifiable,std_arcsec"]
    for axis, ok in sorted(cal.node_identifiable.items()):
        emap = cal.parameters.map(axis)
        node_std = std[axis] if std is not None else cal.node_std(axis)
        for node, value, good, s in zip(np.degrees(emap.nodes), emap.values, ok, node_std):
            s_text = f"{s / ARCSEC:.4f}" if good and np.isfinite(s) else ""
            rows.append(f"{axis},{node:g},{value / ARCSEC:.4f},{int(good)},{s_text}")
    Path(path).write_text("\n".join(rows) + "\n")


def write_calibration(cal: Calibration, arm: Arm, folder: str | Path, force: bool = False,
                      report: dict[str, Any] | None = None) -> Path:
    """Write a calibration folder whole (:func:`~aacmm_pin.data.output_folder.output_folder`); return it.

    Files: ``parameters.json``, ``calibrated.urdf``, ``encoder_maps.csv``, ``report.json``, and
    ``calibrated.sizes.json`` when the arm has a sizes file (:mod:`aacmm_pin.model.sizes`), so that the
    folder's arm keeps its plausible sizes.

    ``report``: further keys of ``report.json`` (``identify``'s ``model_choice``).

    Raises:
        OutputExistsError: if ``folder`` holds files and not ``force``.
    """
    with output_folder(folder, force) as tmp:
        write_calibration_files(cal, arm, tmp, report)
    return Path(folder)


def write_calibration_files(cal: Calibration, arm: Arm, folder: Path,
                            extra: dict[str, Any] | None = None) -> None:
    """Write the files of a calibration folder into an existing ``folder`` (not atomically).

    ``parameters.json`` names the plugins of the extensions' effects that are not built in
    (:func:`aacmm_pin.effects.registry.write_parameters`). ``calibrated.urdf``'s relative mesh
    and texture paths are rewritten to hold from ``folder`` (or a folder beside it, as the
    temporary folder of :func:`write_calibration` is: :mod:`aacmm_pin.outputs.urdf_resources`).
    """
    params = cal.parameters
    tree = arm.urdf_tree(params.dh, tools=params.tool_vectors(arm))
    rebase_resources(tree.root, Path(str(arm.source)).parent, folder)  # meshes found from here
    (folder / URDF_FILE).write_text(tree.xml(), encoding="utf-8")
    if arm.sizes_file is not None:  # beside the URDF or given (--sizes): the folder carries it
        write_sizes(arm.sizes, sizes_path(folder / URDF_FILE))
    write_parameters(params.replace(arm=URDF_FILE), folder / PARAMETERS_FILE)
    write_maps_csv(cal, folder / MAPS_FILE)
    report = cal.report()
    report["arm"] = arm.name
    report["sizes"] = arm.sizes_label  # the sizes file the fit used, or the defaults
    if frames := instrument_frames(cal):  # predict --frame GROUP
        report[FRAMES_KEY] = frames
    report.update(extra or {})
    (folder / REPORT_FILE).write_text(json.dumps(report, indent=2) + "\n")
