r"""One solve of a problem: scipy's trust region with the Jacobians' memory kept apart.

:class:`SolveRun` is :meth:`aacmm_pin.fit.solver.Problem.solve`'s state (the evaluations, the
lowest cost, the last residual) and the residual and Jacobian functions it gives scipy;
:class:`HeldJacobians` holds the data Jacobians of the run (the operator's current one, the one
taken in the residual's pass) and releases them, so that a large campaign's Jacobian (hundreds of
MB) never lives twice; :class:`_Handover` serves a warm start's residual and Jacobian once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import numpy as np
from scipy.sparse.linalg import LinearOperator

from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian, DataJacobian
from aacmm_pin.fit.reduced_jacobian import ReducedJacobian
from aacmm_pin.fit.solver_values import BudgetSpent, Solution, SolverSettings, WarmStart

if TYPE_CHECKING:
    from scipy.optimize import OptimizeResult

T = TypeVar("T")

STEP_TOL = 1e-4
"""A solve ends at an accepted point when no reduced coordinate's Gauss-Newton step from it exceeds
this many standard deviations: scipy's ``gtol`` (on the largest entry of the gradient
``(J P)^T f``) set to ``STEP_TOL`` x the solve's sigma. The columns of ``J P`` are nearly
orthonormal and every row's noise is the solve's sigma, so the gradient is about minus the
Gauss-Newton step and each reduced coordinate's standard deviation is about sigma. It is as strict
as scipy's ``ftol`` of 1e-12 on these problems (a cost change of 1e-12 is a step of 0.7e-4 to 7e-4
sigma for 1,600 to 160,000 samples), but it does not wait for the cost: below such a step the
cost's change is its rounding, and the trust region rejected steps at random until the step's
tolerance stopped it (5 to 13 evaluations at every size, depending on the noise, the last ones
moving nothing)."""
BUDGET_MESSAGE = "The maximum number of function evaluations is exceeded."
"""scipy's message for a solve stopped at its cap, also given when the fit's budget is spent."""


class _Handover:
    """A warm start's residual and Jacobian for scipy's first calls.

    Each is served to the first call of its kind if that call is at the start exactly, and
    released after it.
    """

    def __init__(self, warm: WarmStart, jacobian: bool):
        self.z = np.array(warm.z, dtype=float)
        self._residual = [] if warm.residual is None else [warm.residual]
        self._jacobian = [] if warm.jacobian is None or not jacobian else [warm.jacobian]

    def _take(self, held: list[T], z: np.ndarray) -> T | None:
        given = held.pop() if held else None
        return given if given is not None and np.array_equal(self.z, z) else None

    def residual(self, z: np.ndarray) -> np.ndarray | None:
        """Return the start's residual on the first call if z is the start, else None."""
        return self._take(self._residual, z)

    def jacobian(self, z: np.ndarray) -> DataJacobian | None:
        """Return the start's data Jacobian on the first call if z is the start, else None."""
        return self._take(self._jacobian, z)


class HeldJacobians:
    """The data Jacobians a solve holds, released as soon as no step needs them.

    scipy keeps the first Jacobian and the current one while it builds the next: only the current
    one is used, so the operator's earlier data Jacobian is released (emptied) before the next is
    taken (:meth:`hold`), and a Jacobian taken in a residual's pass is kept only until the
    operator at that point takes it (:meth:`take_fused`).
    """

    def __init__(self) -> None:
        self._held: list[DataJacobian] | None = None
        self._at: np.ndarray | None = None
        self._fused: tuple[np.ndarray, ChunkedJacobian] | None = None
        self.from_caller = False
        """Whether the current operator holds the caller's (maybe inexact) Jacobian."""

    def release(self) -> None:
        """Empty the current operator's Jacobian (its memory is freed)."""
        if self._held is not None:
            self._held.clear()
            self._held = None

    def hold(self, held: list[DataJacobian], z: np.ndarray, from_caller: bool) -> None:
        """Keep the list holding the current operator's data Jacobian, taken at z."""
        self._held, self._at, self.from_caller = held, np.array(z, dtype=float), from_caller

    def keep_fused(self, z: np.ndarray, jac: ChunkedJacobian) -> None:
        """Keep the data Jacobian a residual's pass took at z (for the operator at z)."""
        self._fused = (np.array(z, dtype=float), jac)

    def take_fused(self, z: np.ndarray) -> ChunkedJacobian | None:
        """Return the residual's pass' Jacobian if it was taken at z (else None); drop it."""
        fused, self._fused = self._fused, None
        return fused[1] if fused is not None and np.array_equal(fused[0], z) else None

    def drop_fused(self) -> None:
        """Drop a residual's pass' Jacobian that no operator took."""
        self._fused = None

    def last(self, x: np.ndarray, exact: bool) -> tuple[bool, DataJacobian | None]:
        """Release the current Jacobian; return whether one was held and it, if taken at x.

        ``exact``: whether a caller's Jacobian (a warm start's) is exactly the one at its point.
        """
        held, self._held = self._held, None
        if held is None:
            return False, None
        last = (held[0] if held and self._at is not None and np.array_equal(self._at, x)
                and (exact or not self.from_caller) else None)
        held.clear()
        return True, last


class SolveRun:
    """One :meth:`~aacmm_pin.fit.solver.Problem.solve`: its state and scipy's functions.

    Args:
        problem: the problem (a :class:`~aacmm_pin.fit.solver.Problem`: preconditioned).
        start: the start, reduced coordinates, shape (n_z,), or a :class:`WarmStart` (not kept:
            its Jacobian is handed to scipy's first step and then freed).
        settings: loss, its scale and the evaluation budget.
        jac: ``"analytic"`` or a scipy finite-difference scheme (``"2-point"``, ...).
        on_evaluation: called after every residual evaluation with the residual's RMS.
    """

    def __init__(self, problem: ReducedJacobian, start: WarmStart | np.ndarray, settings: SolverSettings,
                 jac: str, on_evaluation: Callable[[float], None] | None):
        warm = start if isinstance(start, WarmStart) else WarmStart(np.asarray(start))
        self.problem, self.settings, self.jac, self.on_evaluation = problem, settings, jac, on_evaluation
        # The analytic Jacobian goes to LSMR as an operator at every size: in the preconditioned
        # coordinates its columns are nearly orthonormal, so LSMR takes a few products per step
        # where the exact solver takes a dense SVD (paper-sized campaign: 3x less CPU, the same
        # solution to 1e-4 of its standard deviations, tests/test_identification.py)
        self.dense = jac != "analytic"
        self.z0 = warm.z
        self.handover = _Handover(warm, jacobian=not self.dense)
        self.exact = warm.at is None or np.array_equal(warm.at, problem.x(self.z0))
        self.evaluations = 0
        self.best: tuple[float, np.ndarray, np.ndarray] | None = None
        """(cost, z, f) of the lowest cost."""
        self.latest: tuple[np.ndarray, np.ndarray] | None = None
        """(z, f) of the last evaluation."""
        # a chunked problem's steps from its normal equations (a linear loss: a robust loss
        # reweights the rows, which the normal equations do not keep)
        self.normal_equations = problem.chunked and settings.loss == "linear"
        self.fuse = self.normal_equations and jac == "analytic"  # residuals with their products
        self.jacobians = HeldJacobians()

    def _with_products(self, z: np.ndarray) -> np.ndarray:
        f, jac_z = self.problem.fun_with_products(z)
        self.jacobians.keep_fused(z, jac_z)
        return f

    def fun(self, z: np.ndarray) -> np.ndarray:
        """Return the residual at z (scipy's ``fun``), counting and reporting the evaluation."""
        given = self.handover.residual(z)
        if given is None:
            given = self.problem.fun_reported(z, self.on_evaluation,
                                              evaluate=self._with_products if self.fuse else None)
            self.evaluations += 1
        cost = 0.5 * float(given @ given)
        self.latest = (np.array(z, dtype=float), given)
        if self.best is None or cost < self.best[0]:
            self.best = (cost, np.array(z, dtype=float), given)
        return given

    def operator(self, z: np.ndarray) -> LinearOperator:
        """Return the Jacobian at z as an operator (scipy's ``jac``), the previous one released."""
        self.jacobians.release()
        given = self.handover.jacobian(z)
        from_caller = given is not None
        fused = self.jacobians.take_fused(z)
        if fused is not None:  # fun's pass at z: exactly here
            given, from_caller = fused, False
        del fused
        if self.normal_equations:  # scipy evaluated the residual at z just before
            latest = self.latest
            f = (latest[1] if latest is not None and np.array_equal(latest[0], z)
                 else self.problem.fun(z))
            op, held = self.problem.compressed(z, f, given)
        else:
            op, held = self.problem._operator(z, given)
        del given
        self.jacobians.hold(held, z, from_caller)
        return op

    def _at_budget(self) -> OptimizeResult:
        """Return the result of a solve whose fit's evaluations are spent: its lowest cost."""
        self.jacobians.release()
        if self.best is not None:
            cost, z_best, f_best = self.best
        else:  # nothing evaluated here: the start's residual (for the report, not a step)
            z_best = np.array(self.z0, dtype=float)
            f_best = self.problem.fun(z_best)
            cost = 0.5 * float(f_best @ f_best)
        from scipy.optimize import OptimizeResult

        return OptimizeResult(x=z_best, fun=f_best, cost=cost, status=0, success=False,
                              message=BUDGET_MESSAGE, njev=0, optimality=np.nan)

    def run(self) -> Solution:
        """Minimise with scipy's trust-region reflective solver; return its result (:class:`Solution`)."""
        from scipy.optimize import least_squares  # here: reading a calibration needs no solver

        jac_fun: Callable[[np.ndarray], np.ndarray | LinearOperator] | str = self.jac
        if self.jac == "analytic":
            jac_fun = self.problem.jac if self.dense else self.operator
        settings = self.settings
        try:
            out = least_squares(self.fun, self.z0, jac=jac_fun, method="trf",
                                tr_solver="exact" if self.dense else "lsmr", loss=settings.loss,
                                f_scale=settings.f_scale, max_nfev=settings.max_nfev, ftol=1e-12,
                                xtol=1e-12, gtol=STEP_TOL * self.problem.sigma_class)
        except BudgetSpent:  # the fit's evaluations are spent: it ends at its lowest cost
            out = self._at_budget()
        self.jacobians.drop_fused()
        out.nfev = self.evaluations
        held, last = self.jacobians.last(out.x, self.exact)
        if held:  # the last operator's Jacobian, if taken at the solution
            out.pop("jac", None)
        return Solution(out, last)
