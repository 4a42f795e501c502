r"""aacmm-pin-basetemp: an effect on a per-sample column aacmm_pin has never heard of.

The arm's base warms up during a campaign (motors, the operator's hands, the sun on the tripod)
and its rotary encoder A1 (disc and read head on parts that expand differently) reads off by an
angle proportional to the base temperature: :math:`\Delta\theta_1 = c \, (T_{base} - 20\,^\circ C)`.
The temperature is the campaign files' column ``temp_base_c`` (deg C), which the package reads
like every other extra numeric column and hands to the effects as ``samples.column(name)``.

One :class:`~aacmm_pin.AngleTerm` (``basetemp[A1]``, one parameter ``c`` in rad/K) and one
:class:`~aacmm_pin.Effect` (``basetemp``) that proposes it where the base temperature varies, and
offers the residual scan the base temperature as a variable. Installed, the entry point
``basetemp = aacmm_pin_basetemp:BaseTemperature`` in the group ``aacmm_pin.effects``
(``pyproject.toml``) registers it in every process: ``aacmm-pin discover`` tries it, and
``parameters.json`` names this distribution beside the term, so that ``predict``, ``validate`` and
the viewer apply it, or say that it is missing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aacmm_pin import AngleTerm, Effect, MissingColumn, Term, Variable

COLUMN = "temp_base_c"
"""The per-sample column this plugin reads: the temperature of the arm's base, deg C."""
REFERENCE_C = 20.0
"""Temperature at which the A1 angle error is zero, deg C."""
SPAN_C = 0.05
"""A base temperature that spans less than this (deg C) cannot show the error."""
KEY = "basetemp[A1]"
"""The term's key in ``parameters.json`` ``extensions``."""
VARIABLE = "the base temperature"
"""The residual scan's name of the base temperature."""
PLAUSIBLE = np.radians(5.0 / 3600)
"""Plausible size of c: 5 arcsec per kelvin, rad/K (the prior's scale)."""


def base_temperature(samples: Any) -> np.ndarray | None:
    """Return the samples' base temperature, shape (N,), deg C, or None without the column."""
    try:
        values = samples.column(COLUMN)
    except MissingColumn:  # a KeyError too
        return None
    return np.asarray(values, dtype=float)


def _basis(samples: Any) -> np.ndarray:
    """d(A1 angle)/dc = T_base - 20 deg C, shape (N, 1), K.

    Samples without the column raise :class:`~aacmm_pin.MissingColumn` (``samples.column``), in
    one line naming it and the files that could hold it.
    """
    return (np.asarray(samples.column(COLUMN), dtype=float) - REFERENCE_C)[:, None]


def _variable(samples: Any) -> tuple[str, np.ndarray]:
    """The base temperature (deg C), for figures."""
    return "base temperature (deg C)", _basis(samples)[:, 0] + REFERENCE_C


def basetemp() -> Term:
    """The A1 angle error proportional to the base temperature (one parameter, rad/K)."""
    return AngleTerm(KEY, "basetemp", (f"{KEY}.c",), (float(PLAUSIBLE),),
                     "the A1 encoder reads off in proportion to the base temperature "
                     f"({COLUMN} - 20 deg C)", axes=(1,), follows=(VARIABLE,), basis_of=_basis,
                     variable_of=_variable)


class BaseTemperature(Effect):
    """The A1 encoder error that follows the base temperature (column ``temp_base_c``)."""

    name = "basetemp"
    description = "A1 angle error proportional to the arm base's temperature (temp_base_c)"
    reads = (COLUMN,)

    def candidates(self, arm: Any, samples: Any) -> list[Term]:
        """The term, where the base temperature varies."""
        values = base_temperature(samples)
        return [basetemp()] if values is not None and np.ptp(values) > SPAN_C else []

    def term(self, key: str) -> Term | None:
        """``basetemp[A1]``."""
        return basetemp() if key == KEY else None

    def variables(self, arm: Any, samples: Any) -> list[Variable]:
        """The base temperature, where it varies (the residual scan tests the residual on it)."""
        values = base_temperature(samples)
        if values is None or np.ptp(values) <= SPAN_C:
            return []
        return [Variable(VARIABLE, "A1", "base temperature (deg C)", values)]
