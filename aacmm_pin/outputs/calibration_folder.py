"""A calibration folder (CALDIR) read back: its parameters, its report and its arm's files.

:func:`aacmm_pin.outputs.export.write_calibration` writes a folder of the files named here;
:func:`read_calibration` is how every command that takes a calibration (``predict``, ``validate``,
``view``, ``iso10360 --params``) reads one, from the folder or its ``parameters.json``. Reading
needs neither the identification nor the solver: only the parameters and the report's JSON.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aacmm_pin.data.json_file import JsonKeyError, read_json
from aacmm_pin.effects.parameters_file import check_extensions, read_parameters
from aacmm_pin.errors import FileFormatError
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.parameters import MAX_PARAMETERS_BYTES, Parameters, check_against_arm
from aacmm_pin.model.sizes import sizes_path
from aacmm_pin.units import UM

PARAMETERS_FILE = "parameters.json"
"""The parameters (:func:`aacmm_pin.model.parameters.write_parameters`); names the URDF beside it."""
URDF_FILE = "calibrated.urdf"
"""The arm's URDF with the identified DH values and tool vectors (its sizes file beside it)."""
MAPS_FILE = "encoder_maps.csv"
"""Every estimated encoder map node, its value and uncertainty."""
REPORT_FILE = "report.json"
"""The fit's report (:meth:`aacmm_pin.fit.identification_result.Calibration.report`)."""
COMPACT_URDF_FILE = "compact.urdf"
"""The calibrated URDF with its error frames folded into the joint origins
(:func:`aacmm_pin.model.compact_urdf.compact_urdf`): the user's link and joint names only."""
COMPACT_PARAMETERS_FILE = "compact.json"
"""The parameters of the compact URDF (``"arm": "compact.urdf"``, no DH entries: folded), with
the tool vectors, encoder maps, extension terms and the frame to the instrument."""


@dataclass(frozen=True)
class CalibrationFolder:
    """A calibration read back (:func:`read_calibration`)."""

    parameters: Parameters
    """The parameters; a relative arm path taken relative to the folder."""
    report: dict[str, Any] | None = field(repr=False)
    """The content of ``report.json``; None where there is none to trust (see :func:`read_report`)."""
    folder: Path
    """The folder (that of the parameters file)."""
    urdf: Path | None
    """The folder's ``calibrated.urdf`` as :func:`aacmm_pin.outputs.export.write_calibration` writes it;
    None when there is none (a parameters file alone)."""
    sizes: Path | None
    """The sizes file beside ``urdf`` (``calibrated.sizes.json``); None when there is none."""
    file: Path | None = None
    """The parameters file read (errors name it)."""

    def check(self, arm: Arm) -> None:
        """Check that the parameters fit the arm: its error frames, tools, axes and extensions.

        Raises:
            FileFormatError: naming the parameters file and every key that does not fit.
        """
        check_against_arm(self.parameters, arm)
        check_extensions(self.parameters, arm, self.file)

    @property
    def accuracy(self) -> float | None:
        """The accuracy per coordinate the report claims, m.

        The larger of its ``sigma_um`` (the fit's noise estimate) and ``fit_rms_um``, as
        :attr:`~aacmm_pin.fit.identification_result.Calibration.accuracy`; None without a report or
        with neither as a positive finite number.
        """
        data = self.report or {}
        values = [data.get(key) for key in ("sigma_um", "fit_rms_um")]
        good = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)
                and math.isfinite(v) and v > 0]
        return max(good) * UM if good else None

    @property
    def fitted_with_bar(self) -> bool:
        """Whether the report lists the length bar among the fit's inputs."""
        inputs = (self.report or {}).get("inputs")
        return isinstance(inputs, list) and "bar" in inputs

    @property
    def nest_offsets_um(self) -> dict[str, list[float]]:
        """The estimated offset of every R-Test nest (location -> [dx, dy, dz], um); {} if none."""
        offsets = (self.report or {}).get("nest_offsets_um")
        if not isinstance(offsets, dict):
            return {}
        return {str(k): [float(x) for x in v] for k, v in offsets.items()
                if isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) for x in v)}


def read_calibration(caldir: str | Path) -> CalibrationFolder:
    """Read a calibration folder, or its ``parameters.json`` (or a parameters file of another name).

    Raises:
        FileFormatError: for a missing or bad parameters file (:func:`~aacmm_pin.read_parameters`).
    """
    path = Path(caldir)
    params = read_parameters(path)
    folder = path if path.is_dir() else path.parent
    urdf = folder / URDF_FILE
    sizes = sizes_path(urdf)
    return CalibrationFolder(params, read_report(path), folder, urdf if urdf.is_file() else None,
                             sizes if sizes.is_file() else None,
                             folder / PARAMETERS_FILE if path.is_dir() else path)


def read_report(caldir: str | Path) -> dict[str, Any] | None:
    """Return a calibration folder's ``report.json``, or None where there is none to trust.

    ``caldir`` is the folder or its ``parameters.json`` (a parameters file of another name has no
    report of its own: None, rather than a neighbour's report). None when the report is missing,
    larger than :data:`~aacmm_pin.model.parameters.MAX_PARAMETERS_BYTES`, not a JSON object.
    """
    path = Path(caldir)
    if not path.is_dir() and path.name != PARAMETERS_FILE:
        return None
    report = (path if path.is_dir() else path.parent) / REPORT_FILE
    try:
        # a report lists every outlier sample (3 keys each): its keys grow with the campaign, so
        # only its size bounds them (each object still at most MAX_OBJECT_KEYS keys)
        data = read_json(report, MAX_PARAMETERS_BYTES, "a report", max_file_keys=None)
    except JsonKeyError:
        raise  # well formed but ambiguous: refused, not ignored
    except FileFormatError:
        return None
    return data if isinstance(data, dict) else None
