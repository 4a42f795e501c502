r"""The length bar linearised at a calibration: what a model change does to the bar errors.

Discovery (:mod:`aacmm_pin.analyses.discovery`) scores candidate effects on data the fit did not use; the
length bar is such data. Its errors are dominated by what the SPATs cannot pin down, not by the
model: the R-Test nest positions (known to a few um) set the campaign's scale, and bar postures
often visit encoder readouts no SPAT visited (map nodes held at their start value). A plain RMS of
the bar errors can therefore grow when a correct term is added (a scale error that happened to
cancel the missing effect is uncovered). This module gives the bar errors, their derivatives in the
identification's reduced coordinates, and their predicted covariance

.. math::  C = G \Sigma G^T + C_{unvisited} + C_{held} + C_{socket},

with :math:`\Sigma` the calibration's posterior covariance (data, nest prior, plausible-size prior),
:math:`C_{unvisited}` the plausible sizes of the map nodes no SPAT readout touches,
:math:`C_{held}` those of the directions the constraints hold, less what the fit compensates, and
:math:`C_{socket}` the scatter of each socket's readouts about their mean. The bar error normalised
by C (:math:`\sqrt{e^T C^{-1} e / n}`; at most about 1 when the model explains the bar, below 1
since the plausible sizes are generous) is the measure that shrinks when a missing effect is added,
whatever the nests' scale error.

Bar readouts whose every axis uses only map nodes some SPAT readout touched are "covered"
(:func:`covered_readouts`; on the node grid whether the model has maps or not: for a DH model it
is the SPATs' angle range); the RMS over covered readouts is reported alongside.
"""

from __future__ import annotations

import numpy as np

from aacmm_pin.analyses.validation import bar_pairs, pair_errors, pair_weights
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.effects.base import Term
from aacmm_pin.effects.calibrated import needs_tilts, stylus_jacobians
from aacmm_pin.effects.contract import check_once
from aacmm_pin.fit.identifiability import plausible_sizes
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.unknowns import Unknowns
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.encoder_map import EncoderMap, node_count, touched_nodes
from aacmm_pin.model.kinematics import StylusJacobians
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples
from aacmm_pin.model.sizes import Sizes


def covered_readouts(spat_q: np.ndarray, q: np.ndarray, step_deg: float) -> np.ndarray:
    """Return which readouts use, on every axis, only map nodes that SPAT readouts touched.

    Args:
        spat_q: SPAT readouts, shape (N, n_axes), rad.
        q: readouts to check (e.g. the length bar's), shape (M, n_axes), rad.
        step_deg: map node step, deg.

    Returns:
        Mask, shape (M,).
    """
    seen = touched_nodes(spat_q, step_deg)
    emap = EncoderMap(np.zeros(node_count(step_deg)), step_deg)
    out = np.ones(len(q), dtype=bool)
    for a in range(q.shape[1]):
        lower, upper, frac = emap.neighbours(q[:, a])
        out &= (seen[a, lower] | (frac == 1.0)) & (seen[a, upper] | (frac == 0.0))
    return out


def _socket_covariance(points: np.ndarray, w: np.ndarray, campaign: Campaign) -> np.ndarray:
    """Return the errors' covariance from each socket's mean, shape (n, n), m^2.

    Each socket mean's covariance is the scatter of its points over their count; the pairs that
    share a socket (A-B and A-C) share it, so the matrix is not diagonal. Sockets with one
    readout have no scatter to measure and add nothing.
    """
    log = campaign.lengthbar
    assert log is not None
    out = np.zeros((w.shape[0], w.shape[0]))
    for k in np.unique(log.placement):
        for name in np.unique(log.socket):
            r = np.flatnonzero((log.placement == k) & (log.socket == name))
            if r.size < 2:
                continue
            a = w[:, 3 * r[:, None] + np.arange(3)].sum(axis=1)  # (n, 3): d(errors)/d(mean)
            out += a @ (np.cov(points[r].T) / r.size) @ a.T
    return out


class LinearBar:
    """The bar errors of a calibration, their Jacobian and predicted covariance.

    Args:
        cal: a calibration from :func:`aacmm_pin.identify` (its problem and layout).
        campaign: the campaign, with length-bar readouts.
        arm: the arm.

    Attributes:
        errors: bar errors at the calibration, shape (n,), m (n = 0 when no placement has both
            sockets of a pair).
        jac_z: d(errors)/d(reduced coordinates z of ``cal.problem``), shape (n, n_z). z mixes the
            arm entries and the nest offsets (x = x_ref + P z), so the nests' scale reaches the
            bar through these columns.
        unvisited: covariance of the errors from the map nodes no SPAT readout touches (held at
            their start value), each with its plausible size, shape (n, n), m^2.
        socket: covariance from the scatter of each socket's modelled readouts about their mean
            (probing repeatability, and posture-dependent model error counted once more), shape
            (n, n), m^2.
        covered: which bar readouts the SPATs cover (:func:`covered_readouts`), shape (M,).
        covered_errors: bar errors from the covered readouts only (pairs whose sockets both keep
            one), shape (n_covered,), m.
    """

    def __init__(self, cal: Calibration, campaign: Campaign, arm: Arm):
        log = campaign.lengthbar
        problem, u = cal.problem, cal.unknowns
        assert log is not None
        self.cal, self.arm = cal, arm
        self.samples = Samples.of_log(arm, log)
        self.pairs = bar_pairs(campaign)
        full = Unknowns(arm, u.start, u.map_axes, np.ones_like(u.free), u.terms, self.samples)
        points, jac = full.jacobian(full.full_vector(cal.parameters), log.q)
        self.points = points
        self.errors, unit = pair_errors(points, self.pairs)
        self.covered = covered_readouts(cal.q, log.q, cal.parameters.step_deg)
        self.covered_errors = pair_errors(points, bar_pairs(campaign, self.covered))[0]
        self.w = pair_weights(self.pairs, unit, len(log.q))
        g_full = (np.vstack([jac.rmatmul(row) for row in self.w]) if self.n
                  else np.zeros((0, u.free.size)))
        g_free = g_full[:, u.free]
        self.jac_z = g_free @ problem.p[:problem.n_arm]
        fixed = ~u.free  # map nodes no SPAT readout touches
        g_fixed = g_full[:, fixed] * plausible_sizes(u)[fixed][None, :]
        self.unvisited = g_fixed @ g_fixed.T
        # directions the constraints hold (gauges, what the data cannot see), plausible-scaled:
        # their effect on the bar and on the SPAT data (see covariance)
        held = problem.held  # (n_free, n_held), SI
        _, spat_jac = u.jacobian(cal.x[:problem.n_arm], cal.q)
        self._held_bar = g_free @ held
        self._held_data = spat_jac.matmul(held)
        self.socket = _socket_covariance(points, self.w, campaign)
        self.stylus = stylus_jacobians(arm, cal.parameters, log.q, frame="mt", samples=self.samples)

    @property
    def n(self) -> int:
        """Number of bar errors."""
        return int(self.errors.size)

    @property
    def rms(self) -> float:
        """RMS of the bar errors, m (as :func:`aacmm_pin.validate`)."""
        return float(np.sqrt(np.mean(self.errors ** 2)))

    @property
    def covered_rms(self) -> float | None:
        """RMS of the bar errors from covered readouts only, m, or None if no pair is left."""
        if not self.covered_errors.size:
            return None
        return float(np.sqrt(np.mean(self.covered_errors ** 2)))

    def covariance(self, info_z: np.ndarray, data_jac_z: np.ndarray, sigma: float) -> np.ndarray:
        """Return the predicted covariance of the errors, shape (n, n), m^2.

        One posterior over z and the held directions' coefficients (prior: their plausible
        size): what of a held direction the SPAT data see, the free directions may take over
        (a map constant held by its gauge shows up as the axis offset), what they do not see
        keeps its plausible size; the bar sees whatever the pair leaves.

        Args:
            info_z: information matrix of z (inverse of its posterior covariance), (n_z, n_z).
            data_jac_z: d(SPAT residuals)/dz, data rows only, shape (3N, n_z), m.
            sigma: noise per SPAT coordinate, m.
        """
        jac = np.hstack([self.jac_z, self._held_bar])
        n_z, n_h = info_z.shape[0], self._held_bar.shape[1]
        info = np.zeros((n_z + n_h, n_z + n_h))
        info[:n_z, :n_z] = info_z
        if n_h:
            cross = data_jac_z.T @ self._held_data / sigma ** 2
            info[:n_z, n_z:], info[n_z:, :n_z] = cross, cross.T
            info[n_z:, n_z:] = self._held_data.T @ self._held_data / sigma ** 2 + np.eye(n_h)
        posterior = np.linalg.inv(info)
        cov: np.ndarray = jac @ posterior @ jac.T + self.unvisited + self.socket
        return cov

    def columns(self, term: Term, touched: np.ndarray) -> np.ndarray:
        """Return d(errors)/d(term parameters scaled by their plausible sizes), shape (n, k).

        ``touched``: the map nodes the SPAT readouts touch, shape (n_axes, n_nodes) (a map term's
        parameters, as in discovery's SPAT columns).

        Raises:
            AacmmError: if the term needs a column the bar readouts lack (e.g. ``temp_c``).
        """
        if self.stylus.tilts is None and needs_tilts([term]):  # computed once, when first needed
            self.stylus = stylus_jacobians(self.arm, self.cal.parameters, self.samples.q,
                                           frame="mt", samples=self.samples, tilts=True)
        cols = scaled_columns(term, self.samples, self.stylus, self.cal.parameters, touched,
                              self.arm.sizes)
        out: np.ndarray = self.w @ cols.reshape(3 * self.samples.n, -1)
        return out


def scaled_columns(term: Term, samples: Samples, stylus: StylusJacobians, params: Parameters,
                   touched: np.ndarray, sizes: Sizes) -> np.ndarray:
    """Return d(points)/d(term parameters scaled by the arm's plausible sizes), shape (N, 3, k), m.

    Args:
        term: a candidate term of the effect library.
        samples: the readouts' samples (N).
        stylus: stylus Jacobians at those readouts and ``params``.
        params: the parameters the model is linearised at.
        touched: map nodes the SPAT readouts touch, shape (n_axes, n_nodes): a map term's
            parameters.
        sizes: the arm's plausible sizes (:attr:`aacmm_pin.Arm.sizes`).
    """
    check_once((term,), samples, params)  # columns vs forward change, once per process
    cols: np.ndarray = term.columns(samples, stylus, params, touched) * term.sizes(sizes)
    return cols
