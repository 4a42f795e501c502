"""The least-squares fit of one identification structure: the rounds and the robust loop.

:func:`fit_rounds` decides what the data determine (unvisited nodes, gauges, held directions) and
solves, deciding again where the solution holds another number of directions;
:func:`decision_point` is the Gauss-Newton step where the held directions are checked before the
solve; :func:`reject_outliers` is the robust loop (Huber reweighting, then hard rejection) of
:func:`aacmm_pin.fit.identification.identify`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.sparse as sp

from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit import plausibility
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit.chunked_jacobian import (
    ChunkedJacobian,
    DataJacobian,
    chunked_node_sensitivity,
    is_chunked,
)
from aacmm_pin.fit.solver import Nuisance, Problem, SolverSettings, WarmStart
from aacmm_pin.fit.solver_values import BudgetSpent
from aacmm_pin.fit.unknowns import Unknowns
from aacmm_pin.model.parameters import Parameters

if TYPE_CHECKING:  # the solver is imported where a fit runs
    from scipy.optimize import OptimizeResult


class Fit(NamedTuple):
    """One least-squares identification: its structure, problem and solution."""

    unknowns: Unknowns
    unvisited: np.ndarray
    gauges: list[int]
    obs: ident.Observability
    constraints: sp.csr_matrix
    problem: Problem
    res: OptimizeResult
    x: np.ndarray
    nfev: int
    jac: DataJacobian | None = None
    """The data Jacobian at ``x`` when the fit has it (for the covariance; then released)."""


def fit_rounds(full_u: Unknowns, start: Parameters, q: np.ndarray, measured: np.ndarray,
               nuisance: Nuisance, sigma_class: float, weight: np.ndarray | None,
               keep: np.ndarray | None, settings: SolverSettings, jac: str,
               on_evaluation: Callable[[float], None]) -> Fit:
    """Identify from the start values with the samples of ``keep`` (None: all).

    What the data can determine (unvisited nodes, gauges, held directions) is decided on the
    samples kept: unvisited nodes, gauges and held directions at the start; then the held
    directions are checked where one Gauss-Newton step from the start lands
    (:func:`decision_point`, near the solution), before the solve, and at the solution. A check
    that holds another number of directions decides them again there (and solves again, up to 3
    solves); one that holds as many keeps them, so that the start's directions stand wherever the
    decision does not change.
    """
    rounds = _Rounds(full_u, start, q, measured, nuisance, sigma_class, weight, keep)
    return rounds.solve(rounds.landing(on_evaluation), settings, jac, on_evaluation)


class _Landing(NamedTuple):
    """Where the solves start: the decision checked where the Gauss-Newton step landed."""

    now: _Decision
    z: np.ndarray
    """Reduced coordinates of the start of the first solve."""
    x: np.ndarray
    """Its full vector."""
    f: np.ndarray | None
    """The residual there, when the problem stayed the same."""
    nfev: int
    """Evaluations so far."""
    held: list[DataJacobian]
    """The data Jacobian at x (taken out by the solve: a campaign's can weigh hundreds of MB)."""


class _Rounds:
    """One :func:`fit_rounds`: the layout, the samples kept and the decisions on them."""

    def __init__(self, full_u: Unknowns, start: Parameters, q: np.ndarray, measured: np.ndarray,
                 nuisance: Nuisance, sigma_class: float, weight: np.ndarray | None,
                 keep: np.ndarray | None):
        self.q, self.measured, self.nuisance, self.keep = q, measured, nuisance, keep
        self.sigma_class, self.weight = sigma_class, weight
        self.rows = None if keep is None else np.repeat(keep.astype(float), 3)
        self.unvisited = ident.unvisited_nodes(full_u, q if keep is None else q[keep])
        self.unknowns = full_u.with_fixed(self.unvisited)
        self.n_arm = int(self.unknowns.free.sum())
        self.x_start = np.concatenate([self.unknowns.vector(start),
                                       np.zeros(3 * nuisance.n_nests + 6 * nuisance.n_frames)])
        self.chunked = is_chunked(self.unknowns, len(q))  # a large campaign: never held whole
        # without row weights the solver's data Jacobian is this one: computed once per point
        self.same = self.rows is None and weight is None
        self.gauges: list[int] = []
        self.gauge = sp.csr_matrix((0, self.n_arm))

    def jacobian(self, x: np.ndarray) -> DataJacobian:
        """Return the data Jacobian of the kept rows at the full vector x."""
        jac_x: DataJacobian
        if self.chunked:
            jac_x = ChunkedJacobian(self.unknowns, x[:self.n_arm], self.q)
        else:
            _, jac_x = self.unknowns.jacobian(x[:self.n_arm], self.q)
        return jac_x if self.rows is None else jac_x.scaled(self.rows)

    def decide(self, jac_x: DataJacobian, x: np.ndarray, f_ref: np.ndarray | None = None
               ) -> _Decision:
        """Held directions decided at x (``jac_x``: the Jacobian there), the problem at x."""
        obs = ident.observability(self.unknowns, jac_x, self.gauge, self.sigma_class)
        constraints = sp.csr_matrix(sp.vstack([self.gauge, obs.hold_rows()]))
        return _Decision(obs, constraints, Problem(
            self.unknowns, self.q, self.measured, self.nuisance, constraints, obs.scale,
            self.x_start, x, self.sigma_class, self.weight, jac_x if self.same else None, f_ref))

    def check(self, jac_x: DataJacobian, x: np.ndarray, now: _Decision) -> _Decision | None:
        """The decision taken again at x if x holds another number of directions, else None."""
        held = ident.held_count(self.unknowns, jac_x, self.gauge, self.sigma_class)
        return None if held == now.obs.hold.shape[0] else self.decide(jac_x, x)

    def landing(self, on_evaluation: Callable[[float], None]) -> _Landing:
        """Decide at the start, step (:func:`decision_point`) and check the decision there.

        Raises:
            AacmmError: for inputs that are not this arm's, or in other units (2 evaluations).
        """
        unknowns, keep, sigma_class, same = self.unknowns, self.keep, self.sigma_class, self.same
        jac_now = self.jacobian(self.x_start)
        f_start: np.ndarray | None = None  # the residual at the start, when the fit has it
        if same and isinstance(jac_now, ChunkedJacobian):
            # the first problem's products at the start (J^T of the nuisance columns and of the
            # residual) taken in the gauge check's pass: a pass over the chunks less
            nuis_start, f_start = Problem.data_rows_at(unknowns, self.q, self.measured,
                                                       self.nuisance, sigma_class, self.weight,
                                                       self.x_start)
            jac_now.defer(nuis_start, f_start[:3 * len(self.q)])
            del nuis_start
        self.gauges = ident.gauge_axes(unknowns, jac_now)
        self.gauge = ident.gauge_rows(unknowns, self.gauges)
        now = self.decide(jac_now, self.x_start, f_start)
        n_kept = len(self.q) if keep is None else int(keep.sum())
        plausible = plausibility.plausible_rms(unknowns, jac_now, now.obs.scale, 3 * n_kept)
        landed: list[DataJacobian] = []  # a chunked Jacobian where the step lands, with products
        z_now, f_at, nfev = decision_point(now.problem, jac_now if same else None, on_evaluation,
                                           f_start, landed if same and self.chunked else None)
        f_start = None
        f_now: np.ndarray | None = f_at  # the residual at z_now while the problem stays the same
        x_now = now.problem.x(z_now)
        residual = (f_at[:now.problem.n_data].reshape(-1, 3)  # the same numbers
                    if f_at is not None and now.problem.row_weight is None
                    else now.problem.data_residuals(x_now))
        # inputs that are not this arm's, or in other units, end here (2 evaluations); the scale
        # is the median's, so that a few outliers (the robust loop's business) do not count
        scale = _median_scale(residual, keep)
        if not plausibility.agrees(scale, plausible, sigma_class):
            # a wild sample (a readout of 720 deg) drags the least-squares step and every residual
            # with it, but not the start's: the inputs disagree only if the start's bulk does too
            scale = min(scale, _median_scale(now.problem.data_residuals(self.x_start), keep))
        plausibility.check_agreement(scale, plausible, sigma_class, nfev,
                                     unknowns.arm.sizes_label, unknowns.arm.source)
        if z_now.any():  # the step lowered the cost: check the decision where it landed
            del jac_now  # one Jacobian in memory at a time
            jac_now = landed.pop() if landed else self.jacobian(x_now)
            if same and isinstance(jac_now, ChunkedJacobian):  # one pass serves the check and
                # the solve's first step: J^T J, J^T (nuisance columns) and J^T f there (the
                # residual's own pass where the step landed: no pass here)
                jac_now.products(now.problem.nuisance_jacobian(x_now), f_at[:now.problem.n_data])
            again = self.check(jac_now, x_now, now)
            if again is not None:
                # the solve starts at x_now put on the new constraints (held at the start's
                # values), a held component away from it: x_now's Jacobian still serves the
                # first step
                now, z_now, f_now = again, again.problem.z(x_now), None
        landed.clear()  # a step not taken: its Jacobian is not used
        return _Landing(now, z_now, x_now, f_now, nfev, [jac_now])

    def solve(self, begin: _Landing, settings: SolverSettings, jac: str,
              on_evaluation: Callable[[float], None]) -> Fit:
        """Solve from the landing, deciding again at the solution (up to 3 solves)."""
        now, z_now, x_now, f_now, nfev = begin.now, begin.z, begin.x, begin.f, begin.nfev
        jac_now = begin.held.pop()
        last: DataJacobian | None = None  # the solver's last, taken at its solution
        at_solution: DataJacobian | None = None  # the data Jacobian at the final x (covariance)
        for _round in range(3):  # checked at the solution
            if _round:
                jac_now = last if last is not None else self.jacobian(x_now)
                last = None
                again = self.check(jac_now, x_now, now)
                if again is None or (settings.budget is not None and settings.budget.spent):
                    at_solution = jac_now  # the decision stands (or no evaluation is left)
                    break
                now, z_now, f_now = again, again.problem.z(x_now), None
            # the solve's first Jacobian is this one (handed over, not kept here: a campaign's
            # Jacobian can weigh hundreds of MB)
            handed = [jac_now] if self.same else []
            del jac_now
            solution = now.problem.solve(WarmStart(z_now, f_now, handed.pop() if handed else None,
                                                   x_now), settings, jac,
                                         on_evaluation=on_evaluation)
            f_now = None
            # its last Jacobian, at its solution, is jacobian(x) there without row weights
            res, last = solution.result, solution.jacobian if self.same else None
            del solution
            nfev += res.nfev
            z_now = res.x
            x_now = now.problem.x(z_now)
        else:
            at_solution = last  # three rounds: the last solve's (None if it kept none)
        return Fit(self.unknowns, self.unvisited, self.gauges, now.obs, now.constraints,
                   now.problem, res, x_now, nfev, at_solution if self.same else None)


def _median_scale(residual: np.ndarray, keep: np.ndarray | None) -> float:
    """Median-based scale per coordinate of data residuals, shape (N, 3) m, of the kept rows, m."""
    return rob.robust_scale(np.linalg.norm(residual if keep is None else residual[keep], axis=1))


class _Decision(NamedTuple):
    """What the data determine, decided at one point, and the problem it constrains."""

    obs: ident.Observability
    constraints: sp.csr_matrix
    """Gauge rows, then the held directions' rows, over the free arm entries, (k, n_arm)."""
    problem: Problem
    """Constrained by ``constraints``, preconditioned at the point of the decision."""


def decision_point(problem: Problem, jacobian: DataJacobian | None,
                    on_evaluation: Callable[[float], None], f_start: np.ndarray | None = None,
                    landed: list[DataJacobian] | None = None
                    ) -> tuple[np.ndarray, np.ndarray, int]:
    """Return where the held directions are checked before the solve, its residual, evaluations.

    One Gauss-Newton step of ``problem`` (constrained by the directions held at the start, its
    ``x_ref``, and preconditioned there) from the start: the ``dz`` minimising
    ``||f(0) + J P dz||`` (:meth:`Problem.newton_step`). The residual is nearly linear in the
    errors, so the step lands near the solution (on the benchmark's campaigns, 1,600 to 160,000
    samples, its cost is within 0.2 % of the minimum), where a direction that only the start
    makes degenerate (the nominal tool on the A7 axis hides the A7 rotations) has about the
    singular value it has at the solution. Whether the step is taken depends on no start value
    or data set: only on whether it lowered the sum of squared residuals.

    Args:
        problem: the problem decided at the start (z = 0 is its ``x_ref``, the start).
        jacobian: :meth:`Problem.data_jacobian` at the start when the caller has it,
            shape (3N, n_arm), m per unit.
        on_evaluation: progress, called with the RMS of each of the two residuals (m).
        f_start: :meth:`Problem.fun` at the start when the caller has it (counted and reported
            as an evaluation, not computed again).
        landed: for a chunked problem, a list that receives the data Jacobian where the step
            lands, its products taken in the residual's pass there
            (:meth:`Problem.fun_with_products`); None: the residual alone.

    Returns:
        The reduced coordinates after the step, shape (n_z,), if the step lowered the sum of
        squared residuals, else the start's (zeros); :meth:`Problem.fun` there (the solve from
        that point does not evaluate it again); and the residual evaluations taken (2).
    """
    z0 = np.zeros(problem.p.shape[1])
    f0 = problem.fun_reported(z0, on_evaluation, f_start)
    z1 = problem.newton_step(z0, f0, jacobian)
    del jacobian

    def with_products(z: np.ndarray) -> np.ndarray:
        f, jac_z = problem.fun_with_products(z)
        if landed is not None:
            landed.append(jac_z)
        return f

    try:
        f1 = problem.fun_reported(z1, on_evaluation,
                                  evaluate=with_products if landed is not None else None)
    except BudgetSpent:  # the fit's evaluations are spent: its start stands
        return z0, f0, 1
    # the plain sum of squares even for a robust loss: the point only decides the held directions
    # and starts the solve, which minimises the loss from there
    return (z1, f1, 2) if f1 @ f1 < f0 @ f0 else (z0, f0, 2)


def reject_outliers(first: Fit, fit: Callable[[np.ndarray | None], Fit],
                    reweight: Callable[[Fit, np.ndarray], Fit], base_w: np.ndarray,
                    files: list[str], spent: Callable[[], bool] = lambda: False
                    ) -> tuple[np.ndarray, bool, Fit]:
    """Reject outliers from a least-squares fit (see :mod:`aacmm_pin.fit.robust`).

    Huber reweighting on the least-squares structure until the weights settle (a convex start
    that gross outliers cannot capture), then hard rejection: refit from the start values with
    the samples within ``OUTLIER_K`` robust sigmas, the structure (unvisited nodes, gauges, held
    directions) decided on them, until the rejected set no longer changes. ``fit(keep)``
    identifies from the start values with the samples of ``keep``; ``reweight(fit, w)`` solves
    the same structure again from its solution with sample weights ``w``; ``files``: every
    sample's campaign file, its kind, whose own robust scale (at least the stated noise) judges
    it. Returns the mask of
    samples kept, whether the set settled and the final fit (its ``nfev`` counts every solve).
    ``spent()``: whether the fit's evaluations are spent (the loop ends, not settled).
    """
    now, nfev = first, first.nfev
    n, sigma = len(base_w), first.problem.sigma_class

    def norms_of(f: Fit) -> np.ndarray:
        return rob.whitened_norms(f.problem.data_residuals(f.x), base_w)

    def fraction(f: Fit, kept: int) -> float:
        n_det = int(f.problem.n_arm - f.obs.hold.shape[0] - len(f.gauges) + f.problem.n_frame)
        return float(max(3 * kept + f.problem.n_lengths - n_det, 1) / (3 * kept))

    norms = norms_of(now)
    weight = np.ones(n)
    for _ in range(rob.MAX_HUBER_ITERATIONS):
        if spent():
            return np.ones(n, bool), False, now._replace(nfev=nfev)
        new = rob.huber_weights(norms, rob.kind_scales(norms, files, fraction(now, n), sigma))
        if np.max(np.abs(new - weight)) < rob.WEIGHT_TOL:
            break
        weight = new
        now = reweight(now, weight)
        nfev += now.nfev
        norms = norms_of(now)
    mask, refitted = np.zeros(n, bool), False  # refitted: ``now`` is the fit without ``mask``
    x_arm, q = first.x[:first.problem.n_arm], first.problem.q
    if first.problem.chunked:  # a large campaign's node sensitivities chunk by chunk
        sensitivity = chunked_node_sensitivity(ChunkedJacobian(first.unknowns, x_arm, q))
    else:
        sensitivity = rob.node_sensitivity(first.unknowns.jacobian(x_arm, q)[1].nodes, n)
    node_size = float(first.unknowns.arm.sizes.map_node)
    for _ in range(rob.MAX_REJECT_ITERATIONS):
        scale = rob.kind_scales(norms, files, fraction(now, n - int(mask.sum())), sigma)
        unseen = rob.unseen_of_sensitivity(sensitivity, ~mask, node_size) * base_w ** 2
        out = rob.flag_unseen(norms, scale, unseen)
        if refitted and np.array_equal(out, mask):
            return ~mask, True, now._replace(nfev=nfev)
        if not out.any():  # nothing to reject: the least-squares fit stands, if it agrees
            norms = norms_of(first)
            if not rob.flag(norms, rob.kind_scales(norms, files, fraction(first, n), sigma)).any():
                return ~out, True, first._replace(nfev=nfev)
        if spent():
            break
        mask, refitted = out, True
        now = fit(~mask)
        nfev += now.nfev
        norms = norms_of(now)
    return ~mask, False, now._replace(nfev=nfev)
