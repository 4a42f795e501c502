r"""Every named term earned: backward elimination of a discovered model's extension terms.

A discovery step names the best term and further terms of its effect while they are significant
given the model of that moment; a term can be significant then only because an effect named later
is still missing (crosstalk of A2 from A1 stands in for A2's gravity compliance until that is
named). After every refit each extension term of the model is tested given all the others: a Wald
F test of its parameters being zero, :math:`F = \hat\theta^T \Sigma_\theta^{-1} \hat\theta / k`
on :math:`(k, 3N - n)` degrees of freedom, with :math:`\Sigma_\theta` the fit's covariance of the
term's k parameters (its sigma estimated from the residual) -- for a term linear in its parameters
the F test of the refit without it. The least significant term is dropped while its p-value is
not below ``alpha / m`` (Bonferroni over the m terms tested, the step's family-wise level), and the
model refitted (:func:`eliminate`).

Encoder maps are not tested: a map is named with hundreds of chi-square units and its free nodes
are a gauge-held set, not a term's few parameters.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from aacmm_pin.distributions import f_sf
from aacmm_pin.effects.base import ModelSpec, Term
from aacmm_pin.fit.identification_result import Calibration


@dataclass(frozen=True)
class Dropped:
    """A term named by a step and dropped because it is not significant given the others."""

    term: Term
    p_value: float
    """Wald F test of the term's parameters being zero given every other term of the model."""
    named_in: int
    """Step (1-based) that named the term."""
    threshold: float
    """The p-value it needed to stay (alpha over the number of terms tested)."""

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form."""
        return {"term": self.term.key, "p_value": self.p_value, "named_in_step": self.named_in,
                "needed": self.threshold}


def term_p_value(cal: Calibration, term: Term) -> float:
    """Return the p-value of a fitted term's parameters being zero given the rest of the model.

    Args:
        cal: a calibration whose extensions hold ``term`` (its names in ``cal.names``).
        term: the term tested.

    Returns:
        The Wald F test's p-value (1 when the fit does not estimate the term's parameters).
    """
    index = {name: i for i, name in enumerate(cal.names)}
    at = [index[n] for n in term.names if n in index]
    if not at:
        return 1.0
    theta = cal.x[at]
    cov = cal.covariance[np.ix_(at, at)]
    k = int(np.linalg.matrix_rank(cov))
    if k == 0:
        return 1.0
    wald = float(theta @ np.linalg.pinv(cov) @ theta)
    dof = max(cal.fun.size - len(cal.x), 1)
    return float(f_sf(wald / k, k, dof))


def eliminate(cal: Calibration, spec: ModelSpec, refit: Callable[[ModelSpec], Calibration],
              alpha: float, named_in: dict[str, int]
              ) -> tuple[Calibration, ModelSpec, list[Dropped]]:
    """Drop, one at a time, the extension terms not significant given the others, refitting.

    Args:
        cal: the fit of ``spec``.
        spec: the model (its ``terms`` are tested).
        refit: fits a model (as the discovery loop does).
        alpha: the family-wise level of the tests (Bonferroni over the terms tested).
        named_in: term key -> step (1-based) that named it.

    Returns:
        The fit and the model that remain, and the terms dropped (in order).
    """
    dropped: list[Dropped] = []
    while spec.terms:
        p_values = [term_p_value(cal, t) for t in spec.terms]
        worst = int(np.argmax(p_values))
        threshold = alpha / len(spec.terms)
        if p_values[worst] < threshold:
            break
        term = spec.terms[worst]
        dropped.append(Dropped(term, p_values[worst], named_in.get(term.key, 0), threshold))
        spec = dataclasses.replace(spec, terms=tuple(t for t in spec.terms if t is not term))
        cal = refit(spec)
    return cal, spec, dropped
