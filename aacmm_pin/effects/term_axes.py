"""Whether terms fit an arm: every axis a term acts on is one of the arm's."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

from aacmm_pin.effects.base import Term
from aacmm_pin.errors import ArgumentError

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm


def axes_problem(term: Term, arm: Arm) -> str | None:
    """Return why a term does not fit the arm's axes (an axis beyond it), or None if it does.

    One line naming the term and the arm's axes, e.g. ``'compliance[A7]' acts on axis 7; the arm
    ur5 has 6 axes, A1..A6 (shoulder_pan_joint .. wrist_3_joint)``.
    """
    beyond = [a for a in term.axes if not 1 <= a <= arm.n_axes]
    if not beyond:
        return None
    plain = list(arm.axis_names) == [f"A{a}" for a in range(1, arm.n_axes + 1)]
    names = "" if plain else f" ({arm.axis_names[0]} .. {arm.axis_names[-1]})"
    return (f"{term.key!r} acts on axis {beyond[0]}; the arm {arm.name} has {arm.n_axes} axes, "
            f"A1..A{arm.n_axes}{names}")


def check_terms(terms: Iterable[Term], arm: Arm, where: str) -> None:
    """Check that every term acts on axes of the arm.

    Args:
        terms: the terms (e.g. ``identify``'s ``extensions``, ``--terms``).
        arm: the arm they are to be estimated on.
        where: what gave them, named first in the message (``--terms``, ``extensions``).

    Raises:
        ArgumentError: one line naming ``where``, the first term beyond the arm and its axes.
    """
    for term in terms:
        if (why := axes_problem(term, arm)) is not None:
            raise ArgumentError(f"{where}: {why}")

