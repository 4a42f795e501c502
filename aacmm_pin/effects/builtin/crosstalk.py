"""Crosstalk: the angle of an axis reads wrong by an amount that depends on a neighbour's angle."""

from __future__ import annotations

import re
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.effects.base import AngleTerm, Effect, Term, per_axis, varies
from aacmm_pin.effects.builtin.encoder import ANGLE_SPAN, angle_variable, readout
from aacmm_pin.units import ARCSEC

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

SOURCE_SPAN = np.radians(5.0)
"""A neighbour whose readouts span less than this (rad) cannot show a crosstalk."""


def _neighbour(source: int, samples: Samples) -> np.ndarray:
    theta = samples.q[:, source - 1]
    return np.column_stack([np.cos(theta), np.sin(theta)])


def crosstalk(axis: int, source: int) -> AngleTerm:
    """Angular error of one axis depending on a neighbouring axis' angle (first harmonic)."""
    key = f"crosstalk[A{axis}<-A{source}]"
    return AngleTerm(key, "crosstalk", (f"{key}.cos", f"{key}.sin"), (10 * ARCSEC,) * 2,
                     f"crosstalk: the A{axis} angle reads wrong by an amount that depends on the "
                     f"A{source} angle (e.g. bearing or encoder runout coupled across axes)",
                     axes=(axis, source), follows=(angle_variable(source),),
                     basis_of=partial(_neighbour, source), variable_of=partial(readout, source))


class Crosstalk(Effect):
    """Angular error of an axis that depends on a neighbouring axis' angle."""

    name = "crosstalk"
    needs_encoder = True
    description = "angular error of an axis that depends on a neighbouring axis' angle"

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """A term for each axis and each neighbour (previous, next) that both move."""
        return [crosstalk(a, b) for a in per_axis(arm) for b in (a - 1, a + 1)
                if 1 <= b <= arm.n_axes and varies(samples.q[:, b - 1], SOURCE_SPAN)
                and varies(samples.q[:, a - 1], ANGLE_SPAN)]

    def term(self, key: str) -> Term | None:
        """``crosstalk[A<n><-A<m>]``."""
        match = re.fullmatch(r"crosstalk\[A(\d+)<-A(\d+)\]", key)
        return crosstalk(int(match.group(1)), int(match.group(2))) if match else None
