r"""A fit's residual judged against its stated noise: chi-square, structure along row order, gross size.

Every identification (:func:`aacmm_pin.identify`) ends with :func:`judge_residual` on its whitened
residual (each sample's residual divided by its stated noise per coordinate):

* **chi-square** against the stated noise, :math:`\chi^2 = \sum r^2 / \sigma^2` with the residual
  coordinates less the determined parameters as degrees of freedom; p below
  :data:`NOISE_P` means the residual is above the noise. On its own that is not a failure: a model
  that misses an effect (a DH model on a robot with gravity compliance) leaves such a residual on
  clean data; the message says so with the numbers and advises ``discover``.
* **row order** of each instrument set-up (an R-Test location's SPAT samples, an instrument group's
  points; file order, or ``t_s`` when given, i.e. time): a step (best split point) and a
  linear drift of the residual's three coordinates, each F-tested against the residual's own
  variance (so a wrong stated noise does not look like structure) with a Bonferroni factor over
  the split points, the two shapes and the groups (family-wise false-alarm rate
  :data:`ALPHA_ROW_ORDER`). A residual above the noise that follows row order *and* of which that
  step or drift is the larger part (more than half the sum of squares), and that the order of
  no joint readout or per-sample temperature explains as well, is an instrument that moved (a
  bumped tracker or R-Test): no kinematic model explains a function of the row number, so
  ``success`` is False. Poses measured in a sweep make a model error follow row order too (a
  model error of joint 1 swept once: a step explains 81 % of a sine over one period), but then
  the order of that joint explains it as well; an arm that warms drifts with its temperature's
  order. Those are left to ``discover``. (Observed: a DH model of the real UR5 grid leaves a
  residual 3.2 x the tracker noise of which the best step explains 4 %.)
* **gross size** of absolute points: a fit RMS beyond :data:`MAX_POINTS_FIT_RMS` fails, as
  :data:`aacmm_pin.fit.identification.MAX_FIT_RMS` does for SPAT fits.
* **a robust fit** whose kept residual is above the stated noise fails: its rejection threshold is
  a multiple of a scale the residual set itself, so outliers below it stay (breakdown: half the
  samples off by the same amount leave a scale of half that offset), or the model misses an
  effect, which the rejection then mistakes for outliers.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from aacmm_pin.distributions import chi2_sf, f_sf

NOISE_P = 1e-3
"""A residual whose chi-square p-value against the stated noise is below this does not match it."""
ALPHA_ROW_ORDER = 1e-3
"""Family-wise false-alarm rate of the row-order tests (step and drift, every group)."""
MIN_SEGMENT = 5
"""Fewest samples on either side of a step split."""
MAX_POINTS_FIT_RMS = 10e-3
"""A fit of absolute points whose RMS residual exceeds this (m) reports ``success`` False: robots
leave at most a few mm after a DH calibration (an uncalibrated UR5 is 2.6 mm off, a calibrated
cable-driven WAM about 1.3 mm RMS), so 10 mm is a unit, frame or pairing error of the inputs."""


def p_text(p: float) -> str:
    """Return ``"p = 3.1e-05"``, or ``"p < 1e-300"`` for a p-value that underflows."""
    return f"p = {p:.2g}" if p >= 1e-300 else "p < 1e-300"


class RowOrder(NamedTuple):
    """The strongest structure of a group's residual along its rows."""

    group: int
    """Segment (see :func:`judge_residual`)."""
    shape: str
    """``"step"`` or ``"drift"``."""
    row: int
    """First sample after the step (0-based among the samples judged); for a drift its first one."""
    fraction: float
    """Fraction of the group's residual sum of squares the shape explains."""
    p_value: float
    """Bonferroni-corrected p-value of its F test."""
    size: float
    """Step (difference of the means) or drift over the rows, norm of the whitened 3-D vector."""


class Judgement(NamedTuple):
    """What the residual says about the fit."""

    p_value: float
    """Chi-square p-value of the residual against the stated noise."""
    ratio: float
    """RMS of the whitened residual (1: the stated noise)."""
    dof: int
    """Degrees of freedom of the chi-square."""
    row_order: RowOrder | None
    """The row-order structure that fails the fit, or None."""


def _best_step(r: np.ndarray) -> tuple[float, int, float]:
    """Return the largest step sum of squares of centred rows ``r`` (m, 3), its split, its size."""
    m = len(r)
    c = np.cumsum(r, axis=0)[:-1]
    k = np.arange(1, m)
    diff = c / k[:, None] + c / (m - k)[:, None]  # mean before - mean after (r has zero mean)
    ss = k * (m - k) / m * np.sum(diff ** 2, axis=1)
    ok = (k >= MIN_SEGMENT) & (m - k >= MIN_SEGMENT)
    ss = np.where(ok, ss, -1.0)
    best = int(np.argmax(ss))
    return float(ss[best]), best + 1, float(np.linalg.norm(diff[best]))


def row_order(white: np.ndarray, group: int, n_tests: int) -> RowOrder | None:
    """Return the strongest significant step or drift of one group's whitened residual, or None.

    Args:
        white: whitened residual of the group's samples in file order, shape (m, 3).
        group: the group's id (reported).
        n_tests: number of groups tested (Bonferroni factor).
    """
    m = len(white)
    if m < 2 * MIN_SEGMENT + 1:
        return None
    r = white - white.mean(axis=0)
    total = float(np.sum(r ** 2))
    if total <= 0:
        return None
    dof_res = 3 * m - 3 - 3  # the mean and the shape's 3 coordinates
    step_ss, split, step = _best_step(r)
    x = np.arange(m) - (m - 1) / 2.0
    slope = x @ r / (x @ x)
    drift_ss = float(np.sum(slope ** 2) * (x @ x))
    found = []
    for shape, ss, row, size, factor in (("step", step_ss, split, step, m - 2 * MIN_SEGMENT + 1),
                                         ("drift", drift_ss, 0, float(np.linalg.norm(slope))
                                          * (m - 1), 1)):
        f = (ss / 3) / max((total - ss) / dof_res, 1e-300)
        p = min(float(f_sf(f, 3, dof_res)) * factor * 2 * n_tests, 1.0)
        if p < ALPHA_ROW_ORDER and ss > 0.5 * total:
            found.append(RowOrder(group, shape, row, ss / total, p, size))
    return max(found, key=lambda o: o.fraction) if found else None


def _explained(white: np.ndarray) -> float:
    """Return the larger fraction of a residual (m, 3) that a step or a linear drift explains."""
    r = white - white.mean(axis=0)
    total = float(np.sum(r ** 2))
    if len(r) < 2 * MIN_SEGMENT + 1 or total <= 0:
        return 0.0
    x = np.arange(len(r)) - (len(r) - 1) / 2.0
    slope = x @ r / (x @ x)
    return max(_best_step(r)[0], float(np.sum(slope ** 2) * (x @ x))) / total


def _state_explains(white: np.ndarray, state: np.ndarray | None, rows: np.ndarray,
                    fraction: float) -> bool:
    """Whether the order of one state column explains at least ``fraction`` of ``white`` (m, 3).

    ``rows``: the samples' rows in ``state`` in the order ``white`` is in. Columns constant over
    the rows are skipped; ties are broken against the row order (reversed), so that a column
    with few values does not inherit the row order's structure.
    """
    if state is None:
        return False
    back = -np.arange(len(rows))
    for values in state[rows].T:
        if np.ptp(values) > 0 and _explained(white[np.lexsort((back, values))]) >= fraction:
            return True
    return False


def judge_residual(white: np.ndarray, n_det: int, segment: np.ndarray | None,
                   time: np.ndarray | None = None, state: np.ndarray | None = None) -> Judgement:
    """Judge a whitened residual against the noise and along the row order of each segment.

    Args:
        white: residual of the samples judged divided by their stated noise, shape (N, 3).
        n_det: determined parameters.
        segment: what each sample is measured in, (N,): an index >= 0 per instrument set-up
            (an R-Test location, an instrument group of points), -1 for samples not tested
            (length-bar readouts); None: none tested. ``RowOrder.group`` is this index.
        time: time of each sample, (N,), s; None: the row order is the time order.
        state: what else each sample was measured at, shape (N, k): the joint readouts and
            per-sample variables such as temperatures. A row-order structure that the order of
            one of these explains as well (poses measured in a sweep of a joint, an arm that
            warms over the campaign) is the arm's, not a moved instrument's: left to
            ``discover``. None: row order alone.
    """
    dof = max(white.size - n_det, 1)
    stat = float(np.sum(white ** 2))
    p = float(chi2_sf(stat, dof))
    ratio = float(np.sqrt(stat / max(white.size, 1)))
    worst = None
    if p < NOISE_P and segment is not None:
        order = np.arange(len(white)) if time is None else np.argsort(time, kind="stable")
        groups = [g for g in np.unique(segment) if g >= 0]
        found = []
        for g in groups:
            rows = order[segment[order] == g]
            o = row_order(white[rows], int(g), len(groups))
            if o is not None and not _state_explains(white[rows], state, rows, o.fraction):
                found.append(o._replace(row=int(rows[o.row])))
        worst = max(found, key=lambda o: o.fraction) if found else None
    return Judgement(p, ratio, dof, worst)
