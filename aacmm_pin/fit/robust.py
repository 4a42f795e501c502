r"""Outliers: per-sample residual norms, a robust noise scale, IRLS weights, and where a sample came from.

A sample's three residual coordinates are judged together: its *whitened norm*
:math:`d_i = \lVert r_i \rVert \, w_i / \sigma` (``w_i`` the stated-noise row weight, so ``d`` is
in units of the solve's ``sigma``). Under Gaussian noise of per-coordinate standard deviation
``s``, :math:`d_i^2 / s^2` is chi-square with 3 degrees of freedom, whose median is
:data:`CHI2_3_MEDIAN`; so :func:`robust_scale` estimates ``s`` from the median of :math:`d^2`, which
up to half the samples being gross outliers cannot move. The scale comes from the residuals, not
from the stated noise, because a model that misses an effect (the DH model on an arm with encoder
errors) has residuals above the stated noise on every sample, and those are not outliers. It is
estimated for each *kind* of measurement on its own (:func:`kind_scales`: SPATs, points, length-bar
readouts), never below the kind's stated noise: a kind's stated noise may be off by a factor (a
simulated bar seats its stylus exactly, stated at 2 um), and one scale pooled over the kinds then
judges the SPATs by the bar's scatter
(on clean simulated campaigns: 320-367 of 800 SPATs "suspect", and the robust fit rejected them
all). A kind whose typical sample lies beyond :data:`OUTLIER_K` times its stated noise while
another kind matches its own is not a set of outliers: :func:`whole_kind` names it, and the robust
fit refuses rather than fit without it.

The robust fit (:func:`aacmm_pin.identify` with ``robust=True``) is iteratively reweighted least
squares over the ordinary solver: first Huber weights :math:`\min(1, k_H s / d_i)` (a convex
M-estimate: from a least-squares start corrupted by gross outliers it still converges), then hard
rejection: a sample is an outlier when :math:`d_i > k\,s` (:data:`OUTLIER_K`), weight 0, else 1,
refitted until that set no longer changes. The final solution is plain least squares on the
samples kept, so its covariance and noise estimate mean what they mean without outliers.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from aacmm_pin.data.campaign import Campaign, LengthBarLog, PointLog, SpatLog

CHI2_3_MEDIAN = 2.365973884375338
"""Median of the chi-square distribution with 3 degrees of freedom."""
OUTLIER_K = 5.0
r"""A sample whose whitened residual norm exceeds this many robust sigmas is an outlier (robust
fit) or a suspect (least squares): with 3 Gaussian coordinates :math:`P(\chi_3 > 5) = 1.5 \cdot
10^{-5}`, about one false flag in 70,000 clean samples."""
HUBER_K = 2.0
"""Huber threshold of the first IRLS phase, in robust sigmas of the 3-D norm (the median norm of a
clean sample is 1.54)."""
MAX_HUBER_ITERATIONS = 8
"""Most Huber reweightings before the hard-rejection phase."""
MAX_REJECT_ITERATIONS = 10
"""Most refits of the hard-rejection phase; an outlier set still changing then is reported."""
WEIGHT_TOL = 1e-3
"""Huber reweighting stops when no weight changes by more than this."""


KINDS = {"spat.csv": "SPAT samples", "points.csv": "tool points", "lengthbar.csv": "length-bar readouts"}
"""What each campaign file's samples are called in messages (by :func:`sample_sources`' file)."""


class Outlier(NamedTuple):
    """One sample whose residual is beyond :data:`OUTLIER_K` robust sigmas."""

    file: str
    """The campaign file it came from: ``spat.csv``, ``points.csv`` or ``lengthbar.csv``."""
    line: int | None
    """Its 1-based line in that file (None for a campaign built in code)."""
    row: int
    """Its 0-based row in that file's log (``campaign.spat`` ...)."""
    residual: float
    """Norm of its residual (predicted - measured), m."""
    sigmas: float
    """That norm in robust sigmas of the whitened residual norm."""

    def to_dict(self) -> dict[str, object]:
        """Return the ``report.json`` form ``{"file", "line", "residual_um"}``."""
        return {"file": self.file, "line": self.line, "residual_um": self.residual * 1e6}


def sample_sources(campaign: Campaign, use_bar: bool) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Return the file, line (-1: unknown) and log row of every sample of an identification.

    The order is that of :func:`aacmm_pin.fit.measurements.measurements`: SPAT samples (when the
    campaign has SPATs, or no points), then points, then (``use_bar``) the length-bar readouts.
    """
    files: list[str] = []
    lines, rows = [], []
    logs: list[tuple[str, SpatLog | PointLog | LengthBarLog | None]] = []
    if campaign.spat is not None or campaign.points is None:
        logs.append(("spat.csv", campaign.spat))
    if campaign.points is not None:
        logs.append(("points.csv", campaign.points))
    if use_bar:
        logs.append(("lengthbar.csv", campaign.lengthbar))
    for name, log in logs:
        if log is None:
            continue
        n = len(log.q)
        files += [name] * n
        lines.append(np.full(n, -1) if log.lines is None else np.asarray(log.lines))
        rows.append(np.arange(n))
    if len(lines) == 1:  # one file: its own line numbers, not a copy (8 bytes a sample)
        return files, lines[0], rows[0]
    return files, np.concatenate(lines or [np.zeros(0, int)]), np.concatenate(
        rows or [np.zeros(0, int)])


def whitened_norms(residual: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
    """Return every sample's residual norm times its stated-noise weight, shape (N,), m.

    Args:
        residual: residuals predicted - measured, shape (N, 3), m.
        weight: per sample ``sigma / stated noise``, shape (N,), or None (all 1).
    """
    norms: np.ndarray = np.linalg.norm(residual, axis=1)
    return norms if weight is None else norms * weight


def robust_scale(norms: np.ndarray, dof_fraction: float = 1.0) -> float:
    """Return the per-coordinate noise estimated from the median of the squared norms, m.

    Args:
        norms: whitened residual norms of the samples, shape (N,), m.
        dof_fraction: degrees of freedom over residual coordinates of the fit: the residuals of a
            fit are smaller than the noise by its square root, which this undoes.
    """
    if norms.size == 0:
        return 0.0
    return float(np.sqrt(np.median(norms ** 2) / CHI2_3_MEDIAN / max(dof_fraction, 1e-3)))


def kind_scales(norms: np.ndarray, files: list[str], dof_fraction: float = 1.0, floor: float = 0.0
                ) -> np.ndarray:
    """Return every sample's robust scale: :func:`robust_scale` of the samples of its kind, shape (N,), m.

    With several kinds, a kind that scatters less than its stated noise is judged by the stated
    noise (``floor``): a residual the declared noise explains is no outlier (a simulated bar,
    exact and stated at 2 um, scatters 0.3 um by the model's own error, with tails of 1.8 um). A
    campaign of one kind is judged by its residuals' own scale, not the stated noise (a SPAT of
    0.3 um noise stated at 2 um keeps its 4 um outliers flagged).

    Args:
        norms: whitened residual norms of the samples, shape (N,), m.
        files: the campaign file of every sample (:func:`sample_sources`), length N: its kind.
        dof_fraction: as for :func:`robust_scale` (the whole fit's).
        floor: the stated noise in the whitened units (the solve's sigma), m; 0: none.
    """
    kind = np.asarray(files)
    kinds = list(dict.fromkeys(files))
    if len(kinds) < 2:  # one kind: its scale is the residuals' own, as it always was
        floor = 0.0
    out = np.zeros(norms.size)
    for name in kinds:
        sel = kind == name
        out[sel] = max(robust_scale(norms[sel], dof_fraction), floor)
    return out


def whole_kind(norms: np.ndarray, files: list[str], sigma: float, dof_fraction: float = 1.0
               ) -> str | None:
    """Return why one kind of samples disagrees as a whole with its stated noise, or None.

    Under the stated noises (the whitened norms are in units of the solve's ``sigma``), a kind
    whose robust scale is beyond :data:`OUTLIER_K` times its stated noise while another kind's is
    within that has every typical sample an outlier, which one scale for all samples would reject
    whole: a misstated noise, a unit or an instrument at fault, or a model error only that kind
    sees; rejecting samples cannot mend it. (Every kind beyond: the model misses an effect.)

    Args:
        norms: whitened residual norms, shape (N,), m.
        files: the campaign file of every sample (:func:`sample_sources`), length N.
        sigma: the noise per coordinate a sample of weight 1 has, m.
        dof_fraction: as for :func:`robust_scale`.
    """
    kind = np.asarray(files)
    ratios = {name: robust_scale(norms[kind == name], dof_fraction) / sigma
              for name in dict.fromkeys(files)}
    if len(ratios) < 2:
        return None
    name, ratio = max(ratios.items(), key=lambda kv: kv[1])
    other, best = min(ratios.items(), key=lambda kv: kv[1])
    if ratio > OUTLIER_K >= best:
        return (f"the {KINDS.get(name, name)} ({name}, {int((kind == name).sum())} samples) "
                f"scatter {ratio:.3g} times their stated noise, the {KINDS.get(other, other)} "
                f"{best:.3g} times theirs: the typical one lies beyond {OUTLIER_K:g} stated sigmas, "
                "so the kind disagrees as a whole (its stated noise in campaign.json noise_um, its "
                "units or its instrument); a robust fit rejects samples, not a kind")
    return None


def huber_weights(norms: np.ndarray, scale: float | np.ndarray, k: float = HUBER_K) -> np.ndarray:
    """Return IRLS Huber weights (of the squared residual) ``min(1, k scale / norm)``, shape (N,)."""
    out: np.ndarray = np.minimum(1.0, k * scale / np.maximum(norms, 1e-300))
    return out


def flag(norms: np.ndarray, scale: float | np.ndarray, k: float = OUTLIER_K) -> np.ndarray:
    """Return the mask of samples whose whitened norm exceeds ``k`` robust sigmas, shape (N,).

    ``scale``: one for all samples, or each sample's (:func:`kind_scales`), m.
    """
    out: np.ndarray = norms > k * scale
    return out


def unseen_variance(nodes: sp.spmatrix, kept: np.ndarray, node_size: float) -> np.ndarray:
    """Return what each sample's prediction does not know from the other samples kept, m^2.

    A sample that alone touches a map node determines it: left out, that node is held at zero
    and the sample's residual is that node's error, not an outlier's. So each sample's residual
    is judged against the noise plus, for every node no other sample kept touches, the node's
    plausible size times the sample's sensitivity to it (squared, summed over its coordinates).

    Args:
        nodes: d(positions)/d(map nodes), shape (3N, n_nodes) (every node some sample touches).
        kept: the samples kept, shape (N,), bool.
        node_size: plausible size of a node, rad.
    """
    return unseen_of_sensitivity(node_sensitivity(nodes, kept.size), kept, node_size)


def node_sensitivity(nodes: sp.spmatrix, n: int) -> sp.coo_matrix:
    """Return every sample's squared sensitivity to every node it touches, (N, n_nodes) m^2/rad^2.

    The squares of ``nodes`` (d(positions)/d(map nodes), shape (3N, n_nodes)) summed over each
    sample's three coordinates, duplicates summed (entries sorted by sample, then node).
    """
    coo = sp.coo_matrix(nodes)
    per = sp.coo_matrix((coo.data ** 2, (coo.row // 3, coo.col)), shape=(n, nodes.shape[1]))
    per.sum_duplicates()
    return per


def unseen_of_sensitivity(per: sp.coo_matrix, kept: np.ndarray, node_size: float) -> np.ndarray:
    """:func:`unseen_variance` from :func:`node_sensitivity` (duplicates summed), shape (N,), m^2."""
    n = kept.size
    touches = per.data > 0
    counts = np.bincount(per.col[touches], weights=kept[per.row[touches]].astype(float),
                         minlength=per.shape[1])
    others = counts[per.col] - kept[per.row]
    sole = touches & (others < 0.5)
    out: np.ndarray = np.bincount(per.row, weights=per.data * sole, minlength=n) * node_size ** 2
    return out


def flag_unseen(norms: np.ndarray, scale: float | np.ndarray, unseen: np.ndarray, k: float = OUTLIER_K
                ) -> np.ndarray:
    """Return the samples beyond ``k`` sigmas of the noise and their unseen nodes, shape (N,).

    ``norms`` whitened, ``unseen`` the whitened :func:`unseen_variance`.
    """
    out: np.ndarray = norms ** 2 > k ** 2 * (scale ** 2 + unseen)
    return out


def describe(residual: np.ndarray, norms: np.ndarray, scale: np.ndarray, mask: np.ndarray,
             sources: tuple[list[str], np.ndarray, np.ndarray]) -> tuple[Outlier, ...]:
    """Return the flagged samples as :class:`Outlier` records, most robust sigmas first.

    ``scale``: every sample's robust scale (:func:`kind_scales`), shape (N,), m.
    """
    files, lines, rows = sources
    idx = np.flatnonzero(mask)
    sigmas = np.where(scale[idx] > 0, norms[idx] / np.where(scale[idx] > 0, scale[idx], 1.0), np.inf)
    order = np.argsort(-sigmas, kind="stable")
    return tuple(Outlier(files[i], None if lines[i] < 0 else int(lines[i]), int(rows[i]),
                         float(np.linalg.norm(residual[i])), float(z))
                 for i, z in zip(idx[order], sigmas[order]))
