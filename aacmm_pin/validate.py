"""Length-bar validation (paper Fig. 9): error of the mean socket distances per bar placement."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from aacmm_pin.arm import Arm
from aacmm_pin.campaign import Campaign
from aacmm_pin.effects import Samples
from aacmm_pin.errors import AacmmError
from aacmm_pin.kinematics import predict
from aacmm_pin.parameters import Parameters


@dataclass(frozen=True)
class ValidationResult:
    """Length errors of a calibrated arm on the length bar."""

    placements: list[int]
    """Bar placements, in file order of first appearance."""
    pairs: list[tuple[str, str]]
    """Calibrated socket pairs (from, to), as in bar.csv."""
    errors: np.ndarray
    """Measured minus calibrated distance, shape (n_placements, n_pairs), in m; NaN where a
    placement did not measure both sockets of a pair."""

    @property
    def rms(self) -> float:
        """RMS of all length errors, m (pairs not measured in a placement are left out)."""
        return float(np.sqrt(np.nanmean(self.errors ** 2)))

    @property
    def max_abs(self) -> float:
        """Largest absolute length error, m (pairs not measured in a placement are left out)."""
        return float(np.nanmax(np.abs(self.errors)))

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form: ``{"placements": [{"placement": 1, "AB_um": ..}], "rms_um", ..}``."""
        rows = [{"placement": int(k), **{f"{a}{b}_um": None if np.isnan(e) else float(e * 1e6)
                                         for (a, b), e in zip(self.pairs, errs)}}
                for k, errs in zip(self.placements, self.errors)]
        return {"placements": rows, "rms_um": self.rms * 1e6, "max_abs_um": self.max_abs * 1e6}

    def table(self) -> str:
        """Return a plain-text table of the errors in um."""
        head = "placement " + " ".join(f"{a + '-' + b + ' (um)':>12}" for a, b in self.pairs)
        lines = [head] + [f"{k:>9} " + " ".join(f"{e * 1e6:>12.2f}" for e in errs)
                          for k, errs in zip(self.placements, self.errors)]
        lines.append(f"RMS {self.rms * 1e6:.2f} um, max |error| {self.max_abs * 1e6:.2f} um")
        return "\n".join(lines)


def validate(arm: Arm, params: Parameters, campaign: Campaign) -> ValidationResult:
    """Compare the calibrated arm's mean socket distances with the calibrated bar.

    For every placement, the mean stylus centre of the postures in each socket is taken (r-CS), and
    the distance between the sockets of every pair of bar.csv is compared with its calibrated length.

    Raises:
        AacmmError: if the campaign has no length-bar data.
    """
    log = campaign.lengthbar
    if log is None or not campaign.bar:
        raise AacmmError("the campaign has no length-bar data (lengthbar.csv and bar.csv)")
    points = predict(arm, params, log.q, Samples(arm, log.q, log.temp, log.t))
    placements = list(dict.fromkeys(int(k) for k in log.placement))
    pairs = list(campaign.bar)
    errors = np.full((len(placements), len(pairs)), np.nan)
    for i, k in enumerate(placements):
        here = log.placement == k
        for j, (a, b) in enumerate(pairs):
            sel_a, sel_b = here & (log.socket == a), here & (log.socket == b)
            if sel_a.any() and sel_b.any():
                dist = np.linalg.norm(points[sel_b].mean(axis=0) - points[sel_a].mean(axis=0))
                errors[i, j] = dist - campaign.bar[(a, b)]
    return ValidationResult(placements, pairs, errors)
