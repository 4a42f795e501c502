"""Whether the inputs can be this arm's: checks before, early in and after a fit, from the sizes.

An arm's plausible sizes (:mod:`aacmm_pin.model.sizes`) bound how far its true geometry is from
the nominal one; inputs that the nominal arm cannot come near within them are not this arm's, or
are in other units:

* **Before the fit** (:func:`check_point_spread`): absolute points spread about their centre as
  far as the nominal arm's tool points for the same readouts, to within its plausible errors (a
  fraction of a percent of its reach). A spread :data:`UNIT_FACTOR` times larger or smaller is
  beyond any plausible error and below the smallest unit mix-up (cm for mm: 10x), so the
  point columns are in other units (m in mm columns: 1000x) or the readouts are not this arm's.
* **After the first Gauss-Newton step** (2 evaluations, :func:`check_agreement`): errors of
  plausible size in every parameter at once move the data by ``m`` (RMS per coordinate,
  :func:`plausible_rms`); a model that holds leaves its noise and what it misses, less than what
  it holds. A residual (median-based scale: a few outliers do not count) :data:`DISAGREE_K`
  times ``sqrt(sigma^2 + m^2)`` after a step that is nearly exact for errors of that size is
  not this arm (geometry, axis order) or these columns. Measured ratios (residual after the step
  over ``sqrt(sigma^2 + m^2)``): 0.04 UR5, 0.38 WAM (DH), 0.83 the simulated torso with its
  lateral compliance unmodelled, 0.006 the sample campaign; 151 an AACMM's points fitted with
  the WAM's arm, 524 the WAM's with the AACMM's. Where the arm and columns are right, a residual
  beyond it means the sizes file (or the stated noise) understates the arm's errors.
* **After the fit** (:func:`implausible_values`): an identified error :data:`IMPLAUSIBLE_K`
  times its plausible size is no arm's error: ``success`` False with "units?" advice.
"""

from __future__ import annotations

import numpy as np

from aacmm_pin.fit.chunked_jacobian import DataJacobian
from aacmm_pin.fit.measurements import IdentificationError
from aacmm_pin.fit.unknowns import BASE_NAMES, Unknowns
from aacmm_pin.model.sizes import sizes_path

UNIT_FACTOR = 3.0
"""Largest ratio of the nominal arm's point spread to the measured one (either way) accepted."""
DISAGREE_K = 5.0
"""A residual beyond this many times ``sqrt(sigma^2 + m^2)`` after the first step disagrees."""
IMPLAUSIBLE_K = 50.0
"""An identified error beyond this many plausible sizes is implausible (units?)."""
_UNITS = ((1000.0, "m in mm columns?"), (25.4, "inches in mm columns?"), (10.0, "cm in mm columns?"))

ADVICE = ("check the arm (--arm: its geometry, axis order and tools), the units of the point "
          "columns (mm) and readouts (deg), and which column is which")
"""What to check when the inputs disagree with the arm."""

BUILT_IN = "built-in defaults"
""":attr:`aacmm_pin.model.arm.Arm.sizes_label` of an arm without a sizes file."""


def sizes_remedy(sizes: str, urdf: object = None) -> str:
    """Return where an arm's sizes come from and where larger ones go (for a refusal).

    Args:
        sizes: :attr:`aacmm_pin.model.arm.Arm.sizes_label`.
        urdf: the arm's URDF (:attr:`aacmm_pin.model.arm.Arm.source`), to name its sizes file.
    """
    if sizes == BUILT_IN:
        where = "<urdf>.sizes.json beside its URDF" if urdf is None else \
            f"{sizes_path(str(urdf))}"
        return ("the arm has no sizes file: the built-in sizes are a portable measuring arm's "
                "(tens of um, 0.01 deg); a robot's errors are larger: write its sizes into "
                f"{where} or give --sizes FILE (docs/real-robots.md)")
    return f"widen them in its sizes file {sizes}"


class InputsDisagree(IdentificationError):
    """The data disagree with the arm far beyond its plausible sizes (raised early in a fit)."""


def _spread(points: np.ndarray, group: np.ndarray) -> float:
    """Return the RMS distance of points (N, 3) from their group's centre, m."""
    centred = np.concatenate([points[group == g] - points[group == g].mean(axis=0)
                              for g in np.unique(group)])
    return float(np.sqrt(np.mean(np.sum(centred ** 2, axis=1))))


def check_point_spread(measured: np.ndarray, nominal: np.ndarray, group: np.ndarray,
                       sizes: str) -> None:
    """Raise when measured points spread unlike the nominal arm's points (units, before the fit).

    Args:
        measured: absolute points in their instrument frames, shape (N, 3), m.
        nominal: the nominal arm's tool points for the same readouts, shape (N, 3), m.
        group: instrument group of every point (spreads are taken about each group's centre), (N,).
        sizes: which sizes file the arm uses (for the message).

    Raises:
        IdentificationError: one line with the two spreads and what to check.
    """
    if len(measured) < 2:
        return
    got, want = _spread(measured, group), _spread(nominal, group)
    if got <= 0.0 or want <= 0.0:
        return
    ratio = want / got
    if 1.0 / UNIT_FACTOR <= ratio <= UNIT_FACTOR:
        return
    unit = min(_UNITS, key=lambda u: abs(np.log(ratio / u[0])))[1] if ratio > 1 else ""
    raise IdentificationError(
        f"the points spread {got * 1e3:.4g} mm about their centre, the arm's tool points for the "
        f"same readouts {want * 1e3:.4g} mm ({ratio:.3g} x{'' if ratio > 1 else ' less'}; its "
        f"plausible errors, sizes: {sizes}, allow a few percent): units? {unit} {ADVICE}".replace(
            "?  ", "? "))


def plausible_rms(unknowns: Unknowns, jac: DataJacobian, scale: np.ndarray, n_rows: int) -> float:
    """Return ``m``: the RMS per coordinate that plausible errors of every arm parameter make, m.

    ``sqrt(sum_j s_j^2 |J_j|^2 / n_rows)`` over the free entries but X0 and the translation (the
    instrument's frame, fitted from the data first): the residual an arm whose every error has its
    plausible size ``s_j`` shows before calibration.

    Args:
        unknowns: the layout (free entries as ``jac``'s columns).
        jac: data Jacobian w.r.t. the free entries at the start, shape (n_rows, n_free), m per unit.
        scale: plausible size of every free entry, shape (n_free,).
        n_rows: residual coordinates the Jacobian's rows stand for (kept samples x 3).
    """
    arm = np.array([str(k) not in BASE_NAMES for k in unknowns.keys])
    power = np.diag(jac.normal()) * scale ** 2
    return float(np.sqrt(np.sum(power[arm]) / max(n_rows, 1)))


def agrees(rms: float, plausible: float, sigma: float) -> bool:
    """Whether a residual scale per coordinate (m) is within what noise and plausible errors leave.

    The bound of :func:`check_agreement`: :data:`DISAGREE_K` x hypot(sigma, plausible).
    """
    return rms <= DISAGREE_K * float(np.hypot(sigma, plausible))


def check_agreement(rms: float, plausible: float, sigma: float, evaluations: int,
                    sizes: str, urdf: object = None) -> None:
    """Raise :class:`InputsDisagree` when the residual is far beyond noise and plausible errors.

    Args:
        rms: scale per coordinate of the data residual after the first Gauss-Newton step, m
            (median-based, :func:`aacmm_pin.fit.robust.robust_scale`: outliers do not count).
        plausible: :func:`plausible_rms`, m.
        sigma: stated noise per coordinate, m.
        evaluations: evaluations made so far (for the message).
        sizes: which sizes file the arm uses (for the message).
        urdf: the arm's URDF (for the message).
    """
    if agrees(rms, plausible, sigma):
        return
    # the factor on every size that would make this residual plausible: K hypot(sigma, f m) = rms
    need = np.sqrt(max((rms / DISAGREE_K) ** 2 - sigma ** 2, 0.0)) / plausible if plausible > 0 \
        else np.inf
    raise InputsDisagree(
        f"the inputs disagree: after {evaluations} evaluations the residual is "
        f"{rms * 1e3:.4g} mm per coordinate (median-based), "
        f"{rms / np.hypot(sigma, plausible):.3g} x what the stated noise "
        f"({sigma * 1e6:.3g} um) and errors of plausible size in every parameter "
        f"({plausible * 1e3:.3g} mm, sizes: {sizes}) leave; {ADVICE}; if they are right, the "
        f"arm's sizes understate its errors: sizes {need:.3g} x larger would make this residual "
        f"plausible ({sizes_remedy(sizes, urdf)})")


def implausible_values(unknowns: Unknowns, x_arm: np.ndarray, scale: np.ndarray,
                       sizes: str = BUILT_IN, urdf: object = None) -> str | None:
    """Return a "units?" message when an identified error exceeds :data:`IMPLAUSIBLE_K` sizes.

    Args:
        unknowns: the layout (free entries as ``x_arm``).
        x_arm: identified free arm entries, shape (n_free,), SI.
        scale: plausible size of every free entry, shape (n_free,), SI.
        sizes: which sizes the arm uses (:attr:`aacmm_pin.model.arm.Arm.sizes_label`).
        urdf: the arm's URDF (for the message).

    Returns:
        None when every error but X0 and the translation is within the bound, else one clause
        naming the largest and how many exceed it.
    """
    keys = unknowns.keys
    error = x_arm - unknowns.vector(unknowns.start)
    ratio = np.abs(error) / scale
    ratio[[str(k) in BASE_NAMES for k in keys]] = 0.0
    over = np.flatnonzero(ratio > IMPLAUSIBLE_K)
    if not over.size:
        return None
    worst = int(np.argmax(ratio))
    return (f"units? {over.size} identified errors exceed {IMPLAUSIBLE_K:g} x their plausible "
            f"size, the largest {keys[worst]} by {ratio[worst]:.3g} x ({error[worst]:.4g} SI "
            f"against {scale[worst]:.3g}, sizes: {sizes}): no arm of these sizes has such "
            f"errors; {ADVICE}; if they are right, {sizes_remedy(sizes, urdf)}")
