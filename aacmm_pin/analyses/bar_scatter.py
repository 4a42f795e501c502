"""The bar readouts' scatter about their sockets against the accuracy the calibration claims.

A SPAT residual (a sphere held in its seat while the posture varies) and a length-bar socket's
scatter (the stylus held in a conical socket while the posture varies) measure the same thing on
the same arm: how far the model's stylus centre moves when only the posture changes. So the
readouts should scatter about their socket's mean point by about
``sqrt(accuracy**2 + sigma_socket**2)`` per coordinate: the accuracy the calibration claims (its
fit's noise estimate ``sigma``, the fit RMS with the dof of its determined parameters removed, at
least the fit RMS: :attr:`~aacmm_pin.fit.identification.Calibration.accuracy`, ``report.json``) and
the socket's seating repeatability (``campaign.json``'s ``socket``, else
:data:`aacmm_pin.units.SIGMA_SOCKET`). A much larger scatter means the readouts and the calibration
do not belong together: a unit error in a readout column (the stylus axis A7 in radians moves the
stylus centre by ~70 um, which no per-readout check sees), another arm, or an arm changed since.

**The statistic** is robust: the median over all readouts of ``|p - med| ** 2 * n / (n - 2 + pi/2)``
(p a readout's stylus centre, med the coordinate-wise median point of its socket's n readouts;
the factor corrects, in part, for the median's own scatter), over the median of a chi-square with
3 dof, square-rooted: an RMS per coordinate for Gaussian scatter, read low for few readouts per
socket (simulated, Gaussian: 0.80, 0.85, 0.92, 0.97, 0.99 sigma at n = 2, 3, 5, 10, 20), so the
check errs towards silence there. Not the pooled RMS about the socket
means (also reported): a calibration is worse in postures that use encoder-map nodes its SPATs
left undetermined, a minority of the readouts, which also pull their socket's mean (simulated
campaigns, proposed model, seeds 0-9: pooled ratio up to 7.7, this one at most 2.4), whereas a
readout column in the wrong unit moves every readout.

**The limit** on ratio = statistic / expected is :data:`MODEL_ALLOWANCE` times the ratio that noise
alone exceeds with probability :data:`FALSE_ALARM` at this number of readouts M (the sample median
lies beyond the chi-square quantile F when the (M // 2 + 1)-th order statistic of M uniforms does:
a Beta distribution; the readouts of a socket share its median, so the real false-alarm rate of
the noise part is lower, about 1e-4 in simulations). ``tests/test_validation.py`` prints the
measured clean ratios. The expected scatter includes the R-Test's noise, which bar readouts do not
have: the check could be about 1.4x more sensitive for a calibration at the noise (left as is: the
unit errors it is for give ratios of 8-90).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import betaincinv, chdtri  # not scipy.stats: its import takes ~0.5 s

from aacmm_pin.model.parameters import MAX_PARAMETERS_BYTES
from aacmm_pin.units import UM

FALSE_ALARM = 1e-3
"""False-alarm probability of the noise part of the limit."""
MODEL_ALLOWANCE = 2.5
"""Allowed ratio of the model error in the bar's postures to that in the SPAT postures, which the
calibration fitted. Measured on clean simulated campaigns, seeds 0-9, DH and proposed models:
clean ratio over the noise part at most 1.8 (proposed model on 4 x 50 SPATs, whose maps have many
undetermined nodes: ratio 2.42, limit 3.38; 1.2 on paper-sized campaigns: 1.23, limit 2.65).
The stylus axis in radians gives ratios of 8-90 with the proposed model or an exact DH model
(1.1-10 with a DH model on an arm it does not describe, whose own scatter is ~30 um)."""
CAUSES = "a unit error in a readout column (degrees/radians), a different arm, or an arm changed " \
         "since calibration"
_CHI2_3_MEDIAN = float(chdtri(3, 0.5))  # chdtri(k, q): the chi-square quantile 1 - q


@dataclass(frozen=True)
class SocketScatter:
    """The bar readouts' scatter about their sockets' points, against the expected one."""

    scatter: float
    """Robust scatter of the readouts about their socket's median point, per coordinate, m (see
    the module; 0 without sockets of two readouts or more)."""
    pooled: float
    """RMS scatter per coordinate of all sockets pooled, the dof of the means removed, m."""
    n_readouts: int
    """Readouts counted (those of sockets with two readouts or more)."""
    accuracy: float | None
    """The accuracy per coordinate the calibration claims, m, or None when not known."""
    sigma_socket: float
    """Seating repeatability of the stylus in a socket per coordinate, m."""

    @property
    def expected(self) -> float | None:
        """``sqrt(accuracy**2 + sigma_socket**2)``, m, or None without an accuracy."""
        return None if self.accuracy is None else math.hypot(self.accuracy, self.sigma_socket)

    @property
    def ratio(self) -> float | None:
        """:attr:`scatter` over :attr:`expected`, or None without an accuracy."""
        expected = self.expected
        return None if expected is None else self.scatter / expected

    @property
    def limit(self) -> float:
        """Largest ratio taken for a clean campaign (see the module); inf without readouts."""
        m = self.n_readouts
        if m < 2:
            return math.inf
        k = m // 2 + 1
        quantile = float(chdtri(3, 1.0 - float(betaincinv(k, m - k + 1, 1.0 - FALSE_ALARM))))
        return MODEL_ALLOWANCE * math.sqrt(quantile / _CHI2_3_MEDIAN)

    def warning(self) -> str | None:
        """Return the warning when the ratio exceeds the limit, else None."""
        ratio, expected, accuracy = self.ratio, self.expected, self.accuracy
        if ratio is None or expected is None or accuracy is None or ratio <= self.limit:
            return None
        return (f"lengthbar.csv: the readouts scatter {self.scatter / UM:.3g} um per coordinate "
                f"about their sockets' points, {ratio:.3g} times the {expected / UM:.3g} um "
                f"the calibration claims ({accuracy / UM:.3g} um, socket "
                f"{self.sigma_socket / UM:.3g} um; limit {self.limit:.3g} times): {CAUSES}")

    def summary(self) -> str:
        """Return one line: the scatter, and the expected one and the ratio (or why not)."""
        head = f"socket scatter {self.scatter / UM:.3g} um per coordinate"
        ratio, expected = self.ratio, self.expected
        if ratio is None or expected is None:
            return (head + ": not compared with the calibration's accuracy (none given, e.g. a "
                    "parameters file without its report.json)")
        return head + (f", expected {expected / UM:.3g} um from the calibration: ratio "
                       f"{ratio:.3g} (limit {self.limit:.3g})")

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (um)."""
        expected = self.expected
        return {"scatter_um": self.scatter / UM, "pooled_um": self.pooled / UM,
                "n_readouts": self.n_readouts,
                "expected_um": None if expected is None else expected / UM,
                "accuracy_um": None if self.accuracy is None else self.accuracy / UM,
                "sigma_socket_um": self.sigma_socket / UM, "ratio": self.ratio,
                "limit": None if math.isinf(self.limit) else self.limit,
                "summary": self.summary()}


def socket_scatter(points: np.ndarray, placement: np.ndarray, socket: np.ndarray,
                   accuracy: float | None, sigma_socket: float) -> SocketScatter:
    """Return the scatter of the bar readouts' stylus centres about their sockets' points.

    Args:
        points: modelled stylus centres of the bar readouts, shape (M, 3), m.
        placement: bar placement of each readout, shape (M,).
        socket: socket label of each readout, shape (M,).
        accuracy: the accuracy per coordinate the calibration claims, m, or None when not known.
        sigma_socket: seating repeatability per coordinate, m.
    """
    robust: list[np.ndarray] = []  # |p - median|^2 n / (n - 2 + pi/2): 3 sigma^2 on average
    pooled = [0.0, 0.0]  # sum of |p - mean|^2, dof
    for key in dict.fromkeys(zip(placement.tolist(), socket.tolist())):
        rows = (placement == key[0]) & (socket == key[1])
        n = int(np.sum(rows))
        if n > 1:
            dev = points[rows] - np.median(points[rows], axis=0)
            robust.append(np.sum(dev ** 2, axis=1) * n / (n - 2 + math.pi / 2))
            pooled[0] += float(np.sum((points[rows] - points[rows].mean(axis=0)) ** 2))
            pooled[1] += 3 * (n - 1)
    if not robust:
        return SocketScatter(0.0, 0.0, 0, accuracy, sigma_socket)
    d2 = np.concatenate(robust)
    return SocketScatter(math.sqrt(float(np.median(d2)) / _CHI2_3_MEDIAN),
                         math.sqrt(pooled[0] / pooled[1]), int(d2.size), accuracy, sigma_socket)


def read_report(caldir: str | Path) -> dict[str, Any] | None:
    """Return a calibration folder's ``report.json``, or None where there is none to trust.

    ``caldir`` is the folder or its ``parameters.json`` (a parameters file of another name has no
    report of its own: None, rather than a neighbour's report). None when the report is missing,
    larger than :data:`~aacmm_pin.model.parameters.MAX_PARAMETERS_BYTES`, not a JSON object.
    """
    path = Path(caldir)
    if not path.is_dir() and path.name != "parameters.json":
        return None
    report = (path if path.is_dir() else path.parent) / "report.json"
    try:
        with report.open("rb") as f:
            raw = f.read(MAX_PARAMETERS_BYTES + 1)  # bounded: a huge file or /dev/zero
        data = json.loads(raw.decode("utf-8-sig")) if len(raw) <= MAX_PARAMETERS_BYTES else None
    except (OSError, ValueError, RecursionError):
        return None
    return data if isinstance(data, dict) else None


def read_accuracy(caldir: str | Path) -> float | None:
    """Return the accuracy per coordinate a calibration folder's ``report.json`` claims, m.

    The larger of its ``sigma_um`` (the fit's noise estimate) and ``fit_rms_um``, as
    :attr:`~aacmm_pin.fit.identification.Calibration.accuracy`; None without a report
    (:func:`read_report`) or with neither as a positive finite number.
    """
    data = read_report(caldir) or {}
    values = [data.get(key) for key in ("sigma_um", "fit_rms_um")]
    good = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)
            and math.isfinite(v) and v > 0]
    return max(good) * UM if good else None


def fitted_with_bar(caldir: str | Path) -> bool:
    """Whether the calibration's ``report.json`` lists the length bar among its fit's inputs."""
    inputs = (read_report(caldir) or {}).get("inputs")
    return isinstance(inputs, list) and "bar" in inputs
