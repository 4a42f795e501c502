"""The chi-square and F tails (and Bartlett's test) the fit and the analyses use, from ``scipy.special``.

``scipy.stats`` would give the same numbers, but importing it costs about 0.3 s of CPU (its
distributions, and through them ``scipy.spatial``, ``scipy.interpolate``, ``scipy.ndimage``) on
every ``identify``, more than a paper-sized fit. These functions call the same special functions
``scipy.stats.chi2`` and ``scipy.stats.f`` call, with the same answers outside the support and
for invalid degrees of freedom (``tests/test_distributions.py`` compares them value for value).
All take and return plain floats.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.special import chdtrc, chdtri, fdtr, fdtrc, fdtri, gammaincinv


def _valid(*dofs: float) -> bool:
    return all(d > 0 for d in dofs)  # False for nan too


def chi2_sf(x: float, dof: float) -> float:
    """P(X > x) for X chi-square with ``dof`` degrees of freedom (``scipy.stats.chi2.sf``).

    Args:
        x: the statistic; at or below 0 the probability is 1.
        dof: degrees of freedom, > 0 (else nan).
    """
    if not _valid(dof) or math.isnan(x):
        return math.nan
    if x <= 0:
        return 1.0
    return 0.0 if math.isinf(x) else float(chdtrc(dof, x))


def chi2_isf(p: float, dof: float) -> float:
    """The x with P(X > x) = p, X chi-square with ``dof`` degrees of freedom (``chi2.isf``).

    Args:
        p: tail probability in [0, 1] (else nan); 0 gives inf, 1 gives 0.
        dof: degrees of freedom, > 0 (else nan).
    """
    if not _valid(dof) or not 0 <= p <= 1:
        return math.nan
    return math.inf if p == 0 else 0.0 if p == 1 else float(chdtri(dof, p))


def chi2_ppf(q: float, dof: float) -> float:
    """The x with P(X <= x) = q, X chi-square with ``dof`` degrees of freedom (``chi2.ppf``).

    Args:
        q: probability in [0, 1] (else nan); 0 gives 0, 1 gives inf.
        dof: degrees of freedom, > 0 (else nan).
    """
    if not _valid(dof) or not 0 <= q <= 1:
        return math.nan
    return 0.0 if q == 0 else math.inf if q == 1 else float(2 * gammaincinv(dof / 2, q))


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """P(F > x) for F with (``dfn``, ``dfd``) degrees of freedom (``scipy.stats.f.sf``).

    Args:
        x: the statistic; at or below 0 the probability is 1.
        dfn: numerator degrees of freedom, > 0 (else nan).
        dfd: denominator degrees of freedom, > 0 (else nan).
    """
    if not _valid(dfn, dfd) or math.isnan(x):
        return math.nan
    if x <= 0:
        return 1.0
    return 0.0 if math.isinf(x) else float(fdtrc(dfn, dfd, x))


def f_logsf(x: float, dfn: float, dfd: float) -> float:
    """Return log P(F > x), as ``scipy.stats.f.logsf``.

    Above the median the log of :func:`f_sf` (-inf where it is 0), at or below it log1p of minus
    the lower tail (which keeps tails near 1 exact).
    """
    if not _valid(dfn, dfd) or math.isnan(x) or x <= 0 or math.isinf(x):
        p = f_sf(x, dfn, dfd)
        with np.errstate(divide="ignore"):  # as scipy: log(0) is -inf, silently
            return float(np.log(p))
    if x > fdtri(dfn, dfd, 0.5):
        return float(np.log(fdtrc(dfn, dfd, x)))
    return float(np.log1p(-fdtr(dfn, dfd, x)))


def bartlett_p(groups: Sequence[np.ndarray]) -> float:
    """Return Bartlett's test's p-value that the groups share one variance (``scipy.stats.bartlett``).

    Args:
        groups: k >= 2 samples, each 1-D with at least 2 values (any lengths).

    Returns:
        P(chi-square(k - 1) > T), T Bartlett's statistic; the same operations as scipy's, so the
        same value.
    """
    k = len(groups)
    n = np.array([g.size for g in groups], dtype=float)
    ssq = np.array([np.var(g, ddof=1) for g in groups])
    n_tot = np.sum(n)
    spsq = np.sum((n - 1) * ssq) / (n_tot - k)
    numer = (n_tot - k) * np.log(spsq) - np.sum((n - 1) * np.log(ssq))
    denom = 1 + 1 / (3 * (k - 1)) * (np.sum(1 / (n - 1)) - 1 / (n_tot - k))
    return float(chdtrc(k - 1, numer / denom))
