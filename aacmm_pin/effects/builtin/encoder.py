"""Encoder error: the angular position measurement error of an axis (paper Sections 2-3).

Two forms: the paper's map (:func:`encoder_map`, nodes every few degrees, values in the maps) and
low-order harmonics of the axis' own angle (:func:`encoder_harmonic`, for sparse data). Both
describe the same thing: they share a slot, and a map replaces a harmonic term of its axis.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.data.columns import SUFFIXES
from aacmm_pin.effects.base import (
    AngleTerm,
    Effect,
    MapTerm,
    ModelSpec,
    Term,
    Variable,
    per_axis,
    varies,
)
from aacmm_pin.units import ARCSEC

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

ANGLE_SPAN = np.radians(SUFFIXES["_deg"].min_spread)
"""An axis whose readouts span less than this (rad) cannot show an error of its angle."""


def angle_variable(axis: int) -> str:
    """Return the residual scan's name of an axis' angle."""
    return f"the A{axis} angle"


def readout(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    """Return the label and values (deg) of an axis' readout."""
    return f"A{axis} readout (deg)", np.degrees(samples.q[:, axis - 1])


def _harmonics(axis: int, order: int, samples: Samples) -> np.ndarray:
    theta = samples.q[:, axis - 1]
    return np.column_stack([f(h * theta) for h in range(1, order + 1) for f in (np.cos, np.sin)])


def encoder_map(axis: int) -> MapTerm:
    """The paper's encoder error map of one axis (its nodes are the parameters, in the maps)."""
    return MapTerm(f"encoder_map[A{axis}]", "encoder", (), (),
                   f"angular position measurement error of axis A{axis}: an error that depends on "
                   f"the A{axis} angle (encoder map, nodes every few degrees)", axes=(axis,),
                   follows=(angle_variable(axis),), slot=f"encoder[A{axis}]")


class HarmonicTerm(AngleTerm):
    """Encoder error of one axis as harmonics of its angle (an :class:`AngleTerm`)."""

    @property
    def form(self) -> str:
        """``harmonic``."""
        return "harmonic"

    def in_model(self, model: ModelSpec) -> bool:
        """Whether the axis has a map, or a harmonic term already."""
        return self.axis in model.map_axes or super().in_model(model)


def encoder_harmonic(axis: int, order: int = 3) -> HarmonicTerm:
    """Encoder error of one axis as harmonics 1..order of its angle (for sparse data)."""
    key = f"encoder_harmonic[A{axis}]" if order == 3 else f"encoder_harmonic{order}[A{axis}]"
    return HarmonicTerm(key, "encoder",
                        tuple(f"{key}.{f}{h}" for h in range(1, order + 1) for f in ("cos", "sin")),
                        (20 * ARCSEC,) * (2 * order),
                        f"angular position measurement error of axis A{axis}: harmonics 1..{order} "
                        f"of the A{axis} angle", axes=(axis,), follows=(angle_variable(axis),),
                        slot=f"encoder[A{axis}]", basis_of=partial(_harmonics, axis, order),
                        variable_of=partial(readout, axis))


class Encoder(Effect):
    """Angular position measurement error of an axis (encoder map or harmonics)."""

    name = "encoder"
    needs_encoder = True
    description = "angular position measurement error of an axis (encoder map or harmonics)"

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """A map and harmonics on every axis whose readouts span more than 1 deg."""
        out: list[Term] = []
        for a in per_axis(arm):
            if varies(samples.q[:, a - 1], ANGLE_SPAN):
                out += [encoder_map(a), encoder_harmonic(a)]
        return out

    def term(self, key: str) -> Term | None:
        """``encoder_harmonic[A<n>]`` or ``encoder_harmonic<order>[A<n>]``."""
        import re

        match = re.fullmatch(r"encoder_harmonic(\d*)\[A(\d+)\]", key)
        if not match:
            return None
        return encoder_harmonic(int(match.group(2)), int(match.group(1) or 3))

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """Every axis' angle that spans more than 1 deg."""
        return [Variable(angle_variable(a), f"A{a}", *readout(a, samples))
                for a in per_axis(arm) if varies(samples.q[:, a - 1], ANGLE_SPAN)]
