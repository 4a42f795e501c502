"""The values a solve takes and returns: settings, a warm start, the solution, a factored Jacobian.

:meth:`aacmm_pin.fit.solver.Problem.solve` minimises from a :class:`WarmStart` (scipy's ``x0`` with
the ``f0`` and ``J0`` the caller has there) with :class:`SolverSettings` and returns a
:class:`Solution` (scipy's result and the data Jacobian at the solution, which the caller would
otherwise compute again). :class:`Factor` is what Gauss-Newton refits share.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from aacmm_pin.fit.chunked_jacobian import DataJacobian

if TYPE_CHECKING:  # the solver is imported where a fit runs
    from scipy.optimize import OptimizeResult


@dataclass(frozen=True)
class SolverSettings:
    """How :meth:`~aacmm_pin.fit.solver.Problem.solve` minimises (scipy's ``least_squares`` vocabulary)."""

    loss: str
    """``"linear"`` or a robust loss (``"soft_l1"``, ``"huber"``, ...)."""
    f_scale: float
    """Residual scale of a robust loss, m."""
    max_nfev: int
    """Most residual evaluations of one solve."""
    budget: Budget | None = field(default=None, compare=False)
    """The evaluations left to the whole fit (rounds, robust passes), shared by its solves; None:
    only ``max_nfev`` per solve."""


class Factor(NamedTuple):
    """Reduced QR factors of the dense Jacobian ``J P`` at one point (for Gauss-Newton refits)."""

    q: np.ndarray
    """Orthonormal factor, shape (n_residuals, n_z)."""
    r: np.ndarray
    """Upper triangular factor, shape (n_z, n_z)."""


@dataclass(frozen=True)
class WarmStart:
    """Where a solve starts and what the caller already has there (scipy's ``x0``, ``f0``, ``J0``).

    What is given serves scipy's first call at ``z`` instead of being computed again, and is
    released after it: a caller that wants the Jacobian's memory back keeps no reference to it
    (a campaign's data Jacobian can weigh hundreds of MB).
    """

    z: np.ndarray
    """Start, reduced coordinates, shape (n_z,)."""
    residual: np.ndarray | None = None
    """:meth:`~aacmm_pin.fit.solver.Problem.fun` at ``z``, or None (evaluated)."""
    jacobian: DataJacobian | None = field(default=None, repr=False)
    """:meth:`~aacmm_pin.fit.solver.Problem.data_jacobian` (shape (3N, n_arm), m per unit) at ``at``,
    or None."""
    at: np.ndarray | None = None
    """The full vector where ``jacobian`` was taken; None: ``x(z)``. Another point (a held
    component away) serves scipy's first step only: never returned as the solution's Jacobian."""


@dataclass(frozen=True)
class Solution:
    """What :meth:`~aacmm_pin.fit.solver.Problem.solve` found."""

    result: OptimizeResult
    """scipy's result without its ``jac`` (``nfev``: the residual evaluations made; ``status`` 1
    when it ended on :data:`STEP_TOL`)."""
    jacobian: DataJacobian | None = field(default=None, repr=False)
    """:meth:`~aacmm_pin.fit.solver.Problem.data_jacobian` at the solution when the solver's last
    Jacobian was taken there (analytic Jacobian), else None: a caller that needs it there need not
    compute it again."""


class BudgetSpent(Exception):
    """Raised before an evaluation that would exceed a fit's :class:`Budget` (caught in the fit)."""


class Budget:
    """The residual evaluations one identification may make in all (``max_nfev``), and those made.

    Every evaluation of every solve of the fit (the decision point, the rounds, the robust passes,
    the refit with fixed nests) takes one; one more raises :class:`BudgetSpent` before it is made.
    """

    def __init__(self, cap: int):
        self.cap = int(cap)
        """Most evaluations."""
        self.used = 0
        """Evaluations made."""

    @property
    def spent(self) -> bool:
        """Whether no evaluation is left."""
        return self.used >= self.cap

    def take(self) -> None:
        """Count one evaluation, or raise :class:`BudgetSpent` if none is left."""
        if self.spent:
            raise BudgetSpent(f"the fit's {self.cap} evaluations are spent")
        self.used += 1


class Counted:
    """An ``on_evaluation`` callback that takes each evaluation from a :class:`Budget` first.

    :meth:`~aacmm_pin.fit.solver.Problem.fun_reported` calls :meth:`Budget.take` before it
    evaluates and this object, with the residual's RMS (m), after.
    """

    def __init__(self, budget: Budget, report: Callable[[float], None] | None = None):
        self.budget = budget
        self.report = report

    def __call__(self, rms: float) -> None:
        """Report one evaluation's residual RMS (m), already taken from the budget."""
        if self.report is not None:
            self.report(rms)
