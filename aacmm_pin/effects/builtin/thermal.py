"""Thermal expansion: every length of the arm scales with its temperature (``temp_c``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.data.columns import column
from aacmm_pin.effects.base import Effect, ScaleTerm, Term, Variable, varies
from aacmm_pin.errors import MissingColumn
from aacmm_pin.units import REFERENCE_TEMPERATURE_C

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

TEMPERATURE_SPAN_C = column("temp_c").min_spread
"""A temperature that spans less than this (deg C) cannot show an expansion."""
VARIABLE = "temperature"
"""The residual scan's name of the arm temperature."""


def _temperature(samples: Samples) -> np.ndarray:
    if samples.temp is None:
        raise MissingColumn("temp_c", "the model has a thermal term: the readouts need a temp_c "
                                      "column")
    return (samples.temp - REFERENCE_TEMPERATURE_C)[:, None]


def _temperature_variable(samples: Samples) -> tuple[str, np.ndarray]:
    return "arm temperature (deg C)", _temperature(samples)[:, 0] + REFERENCE_TEMPERATURE_C


def thermal() -> ScaleTerm:
    """Uniform thermal expansion of every length: scale ``1 + alpha (T - 20 deg C)``."""
    return ScaleTerm("thermal", "thermal", ("thermal.alpha",), (2.3e-5,),
                     "thermal expansion: every length of the arm scales with its temperature "
                     "(1 + alpha (T - 20 deg C))", follows=(VARIABLE,), basis_of=_temperature,
                     variable_of=_temperature_variable)


class Thermal(Effect):
    """Thermal expansion of the arm's lengths with the temp_c column."""

    name = "thermal"
    description = "thermal expansion of the arm's lengths with the temp_c column"
    reads = ("temp_c",)

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """The term when the temperature varies."""
        return [thermal()] if samples.temp is not None and varies(samples.temp, TEMPERATURE_SPAN_C) \
            else []

    def term(self, key: str) -> Term | None:
        """``thermal``."""
        return thermal() if key == "thermal" else None

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """The arm temperature, where it varies."""
        if samples.temp is None or not varies(samples.temp, TEMPERATURE_SPAN_C):
            return []
        return [Variable(VARIABLE, "all", "arm temperature (deg C)", samples.temp)]
