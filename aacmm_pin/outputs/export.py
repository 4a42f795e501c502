"""A calibration folder (CALDIR): parameters, calibrated URDFs, maps CSV and report.

``CALDIR/parameters.json`` names ``calibrated.urdf`` beside it, so the folder is self-contained;
``calibrated.urdf`` holds the identified DH values in its error frames and the identified tool vector
of every tool (it carries no maps: wrap readouts with the maps first, e.g.
:meth:`aacmm_pin.CalibratedArm.true_angles`); ``calibrated.sizes.json`` beside it carries the
arm's plausible sizes, if it has any.
``compact.urdf`` is the same arm with the error frames folded into the joint origins (the user's
names only, :mod:`aacmm_pin.model.compact_urdf`) and ``compact.json`` its parameters (no DH
entries; the tool vectors, maps, extensions and frame to the instrument). Both URDFs say at their top,
and ``report.json`` under ``urdf_alone_loss_um``, how far the URDF alone is from the whole
calibration over the campaign's poses (:mod:`aacmm_pin.analyses.urdf_loss`);
:func:`aacmm_pin.load_calibrated` reads ``compact.json`` for run time.
:func:`read_calibration` (:mod:`aacmm_pin.outputs.calibration_folder`, which needs no identification)
reads a folder back.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from aacmm_pin.analyses.urdf_loss import REPORT_KEY, UrdfLoss, urdf_alone_loss
from aacmm_pin.data.logs import Campaign
from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.effects.parameters_file import write_parameters
from aacmm_pin.errors import MissingColumn
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.compact_urdf import compact_urdf
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples
from aacmm_pin.model.sizes import sizes_path, write_sizes
from aacmm_pin.model.urdf_tree import UrdfTree
from aacmm_pin.outputs.calibration_folder import (
    COMPACT_PARAMETERS_FILE,
    COMPACT_URDF_FILE,
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

__all__ = ["CalibrationFolder", "campaign_poses", "compact_parameters", "read_calibration",
           "write_calibration", "write_calibration_files", "write_maps_csv"]


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
                      report: dict[str, Any] | None = None, campaign: Campaign | None = None
                      ) -> Path:
    """Write a calibration folder whole (:func:`~aacmm_pin.data.output_folder.output_folder`); return it.

    Files: ``parameters.json``, ``calibrated.urdf``, ``compact.urdf``, ``compact.json``,
    ``encoder_maps.csv``, ``report.json``, and ``calibrated.sizes.json`` and ``compact.sizes.json``
    when the arm has a sizes file (:mod:`aacmm_pin.model.sizes`), so that the folder's arms keep
    their plausible sizes.

    Args:
        cal: the calibration.
        arm: the arm it calibrates.
        folder: the folder to write.
        force: replace an existing folder.
        report: further keys of ``report.json`` (``identify``'s ``model_choice``).
        campaign: the campaign the calibration was identified from: its poses (SPAT, points,
            length bar, with their per-sample columns) are those of the URDF-alone loss
            (:func:`write_calibration_files`).

    Raises:
        OutputExistsError: if ``folder`` holds files and not ``force``.
    """
    with output_folder(folder, force) as tmp:
        write_calibration_files(cal, arm, tmp, report, campaign)
    return Path(folder)


def campaign_poses(campaign: Campaign, arm: Arm) -> list[Samples]:
    """Return the samples of every readout of a campaign (SPAT, points, length bar), one per file."""
    logs = (campaign.spat, campaign.points, campaign.lengthbar)
    return [Samples.of_log(arm, log) for log in logs if log is not None]


def write_calibration_files(cal: Calibration, arm: Arm, folder: Path,
                            extra: dict[str, Any] | None = None,
                            campaign: Campaign | None = None) -> None:
    """Write the files of a calibration folder into an existing ``folder`` (not atomically).

    ``parameters.json`` names the plugins of the extensions' effects that are not built in
    (:func:`aacmm_pin.effects.parameters_file.write_parameters`). ``calibrated.urdf``'s relative mesh
    and texture paths are rewritten to hold from ``folder`` (or a folder beside it, as the
    temporary folder of :func:`write_calibration` is: :mod:`aacmm_pin.outputs.urdf_resources`).
    ``compact.urdf`` is ``calibrated.urdf`` with its error frames folded
    (:func:`~aacmm_pin.model.compact_urdf.compact_urdf`), ``compact.json`` its parameters.

    The URDF-alone loss (:func:`~aacmm_pin.analyses.urdf_loss.urdf_alone_loss`) is taken over the
    readouts of ``campaign`` (SPAT, points, length bar), else over the calibration's fitted
    readouts (``cal.q``, without per-sample columns); it is written into ``report.json``
    (``urdf_alone_loss_um``) and at the top of both URDFs.
    """
    params = cal.parameters
    tree = arm.urdf_tree(params.dh, tools=params.tool_vectors(arm))
    rebase_resources(tree.root, Path(str(arm.source)).parent, folder)  # meshes found from here
    compact = compact_urdf(tree)
    # the whole calibration as the folder will predict it: its own URDF's geometry (e.g. for the
    # gravity torques of a compliance term), not the nominal arm's
    written = Arm(tree.copy(), folder / URDF_FILE, arm.name, sizes=arm.sizes_file)
    poses = campaign_poses(campaign, written) if campaign is not None else [Samples(written, cal.q)]
    loss: UrdfLoss | str
    try:
        loss = urdf_alone_loss(written, params, compact, poses)
    except MissingColumn as exc:  # an extension's column the fitted readouts alone do not have
        loss = f"not computed: {exc}"
    if isinstance(loss, UrdfLoss):
        for urdf in (tree, compact):
            urdf.add_comment(loss.comment(COMPACT_PARAMETERS_FILE))
    (folder / URDF_FILE).write_text(tree.xml(), encoding="utf-8")
    (folder / COMPACT_URDF_FILE).write_text(compact.xml(), encoding="utf-8")
    if arm.sizes_file is not None:  # beside the URDF or given (--sizes): the folder carries it
        write_sizes(arm.sizes, sizes_path(folder / URDF_FILE))
        write_sizes(arm.sizes, sizes_path(folder / COMPACT_URDF_FILE))
    write_parameters(params.replace(arm=URDF_FILE), folder / PARAMETERS_FILE)
    write_parameters(compact_parameters(params, arm, compact), folder / COMPACT_PARAMETERS_FILE)
    write_maps_csv(cal, folder / MAPS_FILE)
    report = cal.report()
    report[REPORT_KEY] = loss.to_dict() if isinstance(loss, UrdfLoss) else {"why": loss}
    report["arm"] = arm.name
    report["sizes"] = arm.sizes_label  # the sizes file the fit used, or the defaults
    if frames := instrument_frames(cal):  # predict --frame GROUP
        report[FRAMES_KEY] = frames
    report.update(extra or {})
    (folder / REPORT_FILE).write_text(json.dumps(report, indent=2) + "\n")


def compact_parameters(params: Parameters, arm: Arm, compact: UrdfTree) -> Parameters:
    """Return the parameters of the compact URDF: no DH entries, its tool joints' vectors.

    A tool joint after an error frame has the error frame in its origin (its vector in the new
    parent's frame), so the vectors are read from ``compact``; maps, extensions, the frame to the
    instrument and every other key are ``params``'.
    """
    origins = {j.name: j.origin[:3, 3].copy() for j in compact.joints() if j.name in arm.tool_joints}
    vectors = {name: origins[name] for name in arm.tool_joints}
    changes: dict[str, Any] = ({"tools": vectors} if params.tools else
                               {"tool": vectors[arm.tool_joints[0]]})
    return params.replace(arm=COMPACT_URDF_FILE, dh={}, **changes)
