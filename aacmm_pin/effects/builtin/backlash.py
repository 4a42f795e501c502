"""Backlash: an angular error of an axis whose sign follows the direction it last moved in."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.effects.base import AngleTerm, Effect, Term, Variable, axis_key, per_axis
from aacmm_pin.units import ARCSEC

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

MIN_REVERSALS = 3
"""An axis needs at least this many samples moving each way to show a backlash."""


def direction_variable(axis: int) -> str:
    """Return the residual scan's name of an axis' direction of motion."""
    return f"the direction of motion of A{axis}"


def _direction(axis: int, samples: Samples) -> np.ndarray:
    return samples.direction[:, axis - 1:axis]


def _direction_variable(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    return f"A{axis} direction of motion", samples.direction[:, axis - 1]


def _both_ways(samples: Samples, axis: int) -> bool:
    d = samples.direction[:, axis - 1]
    return bool((d > 0).sum() >= MIN_REVERSALS and (d < 0).sum() >= MIN_REVERSALS)


def backlash(axis: int) -> AngleTerm:
    """Direction-dependent angular error of one axis: ``+-half`` by the direction of motion."""
    key = f"backlash[A{axis}]"
    return AngleTerm(key, "backlash", (f"{key}.half",), (10 * ARCSEC,),
                     f"backlash of axis A{axis}: an angular error whose sign follows the direction "
                     f"in which A{axis} last moved", axes=(axis,), follows=(direction_variable(axis),),
                     basis_of=partial(_direction, axis),
                     variable_of=partial(_direction_variable, axis))


class Backlash(Effect):
    """Direction-dependent angular error of an axis."""

    name = "backlash"
    needs_encoder = True
    description = "direction-dependent angular error of an axis"

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """One term per axis that moved both ways often enough."""
        return [backlash(a) for a in per_axis(arm) if _both_ways(samples, a)]

    def term(self, key: str) -> Term | None:
        """``backlash[A<n>]``."""
        axis = axis_key("backlash", key)
        return None if axis is None else backlash(axis)

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """Each axis' direction of motion, where it moved both ways."""
        return [Variable(direction_variable(a), f"A{a}", *_direction_variable(a, samples), "levels")
                for a in per_axis(arm) if _both_ways(samples, a)]
