r"""Discovery's family-wise false-alarm rate: one stated number, spent once over what is searched.

On a campaign where nothing is missing, :func:`aacmm_pin.discover` raises a false alarm when a step
names a term or when the residual scan of the final model calls it unexplained. The rate
:math:`\alpha` (:data:`FALSE_ALARM`, ``discover --false-alarm``) is split in three shares whose sum
bounds the probability of any alarm (union bound):

* **the search** (:attr:`FalseAlarm.search`): step k names a candidate only if its p-value is below
  ``search / m_k``, :math:`m_k` the candidates it scores (Bonferroni). A step is taken only after
  the one before rejected, and the named terms leave the family (Holm's step-down: the level rises
  as candidates are named), so the share is spent once over the steps; the backward elimination
  after a refit tests at the same share (it only removes terms). The BIC condition and the
  confirmations come on top (they only remove rejections, so the rate stays bounded): the
  held-out groups and the length bar remove a candidate only where they contradict it at 1 %
  (:data:`aacmm_pin.analyses.discovery.CONFIRM`), so that where it is real they cost at most
  2 % of the search's power (as gates, held-out gain plus bar gain > 0, they removed real terms
  whose leave-one-location-out gain swings by hundreds of chi-square units on four locations);
* **the residual's structure** (:attr:`FalseAlarm.structure`): Holm over the scan's variables
  (:func:`aacmm_pin.analyses.residual_scan.scan_residuals`);
* **the residual against the stated noise** (:attr:`FalseAlarm.noise`): its chi-square test.

The shares (:data:`SHARES`): the search 0.1 %, the structure 0.5 % (the out-of-library effects'
only detector), the noise 0.4 % at the default 1 %. A larger search share buys power against
library effects (a one-parameter effect at the size a knowing oracle finds 9 times in 10, searched
among 24 candidates: power 0.40 at 0.1 %, 0.57 at 0.6 %), but at 0.6 % a null campaign of the
test suite (``test_no_false_discovery_from_dh[102]``, from ``dh`` with a bar) names gravity
compliance on A2 at p x m = 0.00101: the search's level stays where it was before the rate was
stated (1e-3 / m per step). The confirmations do not remove that alarm either: its held-out
groups agree with it (p = 0.90 against it) and the bar is worse with it by 2.46 chi-square units,
p = 0.07 against it by the bar's own noise, no contradiction at 1 %. A search share above 0.101 %
names it whatever the confirmations; a fixed-seed null test fails at a rate near the share spent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from aacmm_pin.errors import ArgumentError

FALSE_ALARM = 0.01
"""Default family-wise false-alarm rate of discovery (``discover --false-alarm``)."""
SHARES = (0.1, 0.5, 0.4)
"""Shares of the rate spent on the search, the residual's structure and its noise (sum 1)."""


@dataclass(frozen=True)
class FalseAlarm:
    """Discovery's family-wise false-alarm rate and its split (see the module doc).

    Args:
        rate: the family-wise rate, in (0, 1) (0.01: one null campaign in 100 raises an alarm).

    Raises:
        ArgumentError: for a rate outside (0, 1).
    """

    rate: float = FALSE_ALARM

    def __post_init__(self) -> None:
        if not 0.0 < self.rate < 1.0:
            raise ArgumentError(f"false-alarm rate: between 0 and 1 (e.g. 0.01), got {self.rate}")

    @property
    def search(self) -> float:
        """Family-wise level of the candidates' search over all the steps (Bonferroni per step)."""
        return self.rate * SHARES[0]

    @property
    def structure(self) -> float:
        """Family-wise level of the residual scan's structure tests (Holm over the variables)."""
        return self.rate * SHARES[1]

    @property
    def noise(self) -> float:
        """Level of the residual's chi-square test against the stated noise."""
        return self.rate * SHARES[2]

    def split_text(self) -> str:
        """Return ``1 % family-wise (0.1 % the candidates over the steps, ...)``."""
        return (f"{_percent(self.rate)} family-wise ({_percent(self.search)} the candidates over "
                f"the steps, {_percent(self.structure)} the residual's structure, "
                f"{_percent(self.noise)} its noise)")

    def text(self, searched: int) -> str:
        """Return ``searched 38 candidates at 1 % family-wise (...)``: the printed line."""
        return f"searched {searched} candidates at {self.split_text()}"

    def to_dict(self, searched: int) -> dict[str, Any]:
        """Return ``discovery.json``'s ``"false_alarm"``."""
        return {"rate": self.rate, "search": self.search, "structure": self.structure,
                "noise": self.noise, "candidates_searched": searched}


def _percent(p: float) -> str:
    return f"{100 * p:.3g} %"
