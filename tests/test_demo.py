"""The main job: ``aacmm-pin demo`` runs with no arguments but a folder, prints Fig. 9, writes all."""

from __future__ import annotations

import json

from aacmm_pin.cli import main


def test_demo_prints_table_and_writes_everything(tmp_path, capsys):
    """The demo identifies the paper's 3 models, prints the Fig. 9 table and writes figures, CALDIRs."""
    assert main(["demo", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Length errors on the bar (um), paper Fig. 9" in out
    for label in ("DH only, R-Test", "proposed, no R-Test", "proposed, R-Test"):
        assert label in out
    for fig in ("fig5_rtest_displacement.png", "fig6_encoder_maps.png", "fig9_length_errors.png"):
        assert (tmp_path / fig).stat().st_size > 20_000
    rms = {}
    for folder in ("dh_rtest", "proposed_no_rtest", "proposed_rtest"):
        for name in ("parameters.json", "calibrated.urdf", "compact.json", "compact.urdf",
                     "encoder_maps.csv", "report.json"):
            assert (tmp_path / folder / name).is_file()
        rms[folder] = json.loads((tmp_path / folder / "validation.json").read_text())["rms_um"]
    assert rms["proposed_rtest"] < rms["dh_rtest"]
