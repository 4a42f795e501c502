"""A calibration folder read back (read_calibration) is what write_calibration wrote."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin.outputs.calibration_folder import read_calibration


def test_read_calibration_gives_back_what_write_calibration_wrote(arm: ap.Arm,
                                                                  small_cal: ap.Calibration,
                                                                  tmp_path: Path) -> None:
    """Parameters, report, URDF and the report's accuracy, bar input and nest offsets round-trip,
    from the folder or its parameters.json; a parameters file alone has no report and no URDF."""
    folder = ap.write_calibration(small_cal, arm, tmp_path / "cal")
    for source in (folder, folder / "parameters.json"):
        back = read_calibration(source)
        assert back.parameters.to_dict() == ap.read_parameters(folder).to_dict()
        assert back.folder == folder
        assert back.urdf == folder / "calibrated.urdf" and back.urdf.is_file()
        assert back.report == json.loads((folder / "report.json").read_text())
        assert back.report is not None and back.report["fit_rms_um"] == small_cal.fit_rms * 1e6
        assert back.accuracy == pytest.approx(small_cal.accuracy, rel=1e-12)
        assert back.fitted_with_bar is False
        offsets = small_cal.nest_offsets_um()
        assert back.nest_offsets_um == offsets
        assert all(math.isfinite(x) for v in offsets.values() for x in v)
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(folder / "parameters.json", alone / "mine.json")
    bare = read_calibration(alone / "mine.json")
    assert bare.report is None and bare.accuracy is None and bare.nest_offsets_um == {}
    assert bare.urdf is None and bare.sizes is None
    with pytest.raises(ap.FileFormatError):
        read_calibration(tmp_path / "missing")


def test_a_report_with_every_sample_an_outlier_reads_back(tmp_path: Path) -> None:
    """A report lists each outlier with 3 keys: a robust fit of 20,000 points with a third off
    writes more keys than any hand-written file needs, and the package must read what it wrote."""
    from aacmm_pin.fit.robust import Outlier
    from aacmm_pin.outputs.calibration_folder import read_report

    outliers = [Outlier("points.csv", k + 2, k, 3e-3, 150.0).to_dict() for k in range(20_000)]
    (tmp_path / "report.json").write_text(json.dumps({"success": True, "outliers": outliers}))
    report = read_report(tmp_path)
    assert report is not None and len(report["outliers"]) == 20_000
