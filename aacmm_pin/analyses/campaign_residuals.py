"""A calibration on a campaign: each sample's predicted and measured point, in the calibration's r-CS.

What the viewer draws (:mod:`aacmm_pin.outputs._viewer_scene`) and what a calibration's fit RMS
counts: the SPAT samples' stylus centres against the nests (as the fit estimated them, from
``report.json``'s ``nest_offsets_um``) plus the R-Test displacement, then the absolute points
mapped into the calibration's frame, and the length bar's errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aacmm_pin.analyses.validation import ValidationResult, points_in_main_frame, validate
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.effects.calibrated import predict
from aacmm_pin.fit.measurements import measured_positions
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples


@dataclass(frozen=True, eq=False)
class ModelResiduals:
    """One calibration on the campaign: predicted and measured sphere centres, r-CS, m."""

    label: str
    """Name shown in the scene (a CALDIR's folder name); the scene path is ``models/<label>``."""
    params: Parameters
    """The calibration."""
    arm: Arm
    """Its arm."""
    nest: np.ndarray
    """Zero position of each SPAT sample's R-Test nest, then each absolute point's measured
    position (deviations are magnified about it), shape (N, 3), r-CS, m."""
    predicted: np.ndarray
    """Predicted stylus centre of each SPAT sample, then of each absolute point (points.csv),
    shape (N, 3), r-CS, m."""
    measured: np.ndarray
    """Measured sphere centre (nest + R-Test displacement) of each SPAT sample, then each absolute
    point (mapped into the calibration's frame: :func:`~aacmm_pin.analyses.validation.points_in_main_frame`),
    shape (N, 3), r-CS, m."""
    validation: ValidationResult | None
    """Length-bar errors, or None without a length bar."""
    sockets: dict[tuple[int, str], np.ndarray]
    """(placement, socket) -> mean predicted stylus centre, shape (3,)."""

    @property
    def residual(self) -> np.ndarray:
        """Predicted minus measured, shape (N, 3), m."""
        residual: np.ndarray = self.predicted - self.measured
        return residual

    @property
    def rms(self) -> float:
        """RMS of the residual coordinates, m: ``report.json``'s ``fit_rms_um`` (nests as estimated)."""
        return float(np.sqrt(np.mean(self.residual ** 2))) if len(self.residual) else 0.0


def campaign_residuals(params: Parameters, arm: Arm, campaign: Campaign, label: str = "model",
                       nest_offsets_um: dict[str, list[float]] | None = None) -> ModelResiduals:
    """Evaluate a calibration on a campaign: predicted and measured points, r-CS, m.

    Args:
        params: the calibration (checked against ``arm`` by the caller).
        arm: its arm.
        campaign: the campaign (SPAT, absolute points and/or length bar).
        label: the name it goes by.
        nest_offsets_um: location id (str) -> the fit's offset of its nest, 3 values in um
            (``report.json``'s ``nest_offsets_um``); None or a missing id: no offset.
    """
    nest_offsets_um = nest_offsets_um or {}
    rot, trans = params.rotation(), params.translation
    spat = campaign.spat
    if spat is None:
        empty = np.zeros((0, 3))
        nest, predicted, measured = empty, empty, empty
    else:
        nest = (np.array([campaign.locations[int(m)] for m in spat.location]) - trans) @ rot
        # the nests where the calibration put them (report.json), as its fit RMS counts them
        shift = np.array([nest_offsets_um.get(str(int(m)), [0.0, 0.0, 0.0])
                          for m in spat.location]) * 1e-6
        measured = (measured_positions(campaign) + shift - trans) @ rot
        predicted = predict(arm, params, spat.q, Samples.of_log(arm, spat))
    if campaign.points is not None:  # what a points fit fitted: the points after the SPATs
        pred_pt, meas_pt, _ = points_in_main_frame(arm, params, campaign)
        meas_pt = (meas_pt - trans) @ rot
        nest = np.vstack([nest, meas_pt])
        measured = np.vstack([measured, meas_pt])
        predicted = np.vstack([predicted, (pred_pt - trans) @ rot])
    validation, sockets = None, {}
    bar = campaign.lengthbar
    if bar is not None and campaign.bar:
        validation = validate(arm, params, campaign)
        points = predict(arm, params, bar.q, Samples.of_log(arm, bar))
        for k, s in dict.fromkeys(zip(bar.placement.tolist(), bar.socket.tolist())):
            sockets[(int(k), str(s))] = points[(bar.placement == k) & (bar.socket == s)].mean(axis=0)
    return ModelResiduals(label, params, arm, nest, predicted, measured, validation, sockets)


