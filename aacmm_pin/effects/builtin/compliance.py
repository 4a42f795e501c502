"""Gravity compliance: a joint deflects about its own axis by k times the gravity torque on it."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.data.columns import SUFFIXES
from aacmm_pin.effects.base import AngleTerm, Effect, Term, Variable, axis_key, per_axis, varies

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

TORQUE_SPAN = SUFFIXES["_n_m"].min_spread
"""A gravity torque that spans less than this (N m) over the samples cannot show a compliance."""


def torque_variable(axis: int) -> str:
    """Return the residual scan's name of the gravity torque on an axis."""
    return f"the gravity torque on A{axis}"


def _gravity(axis: int, samples: Samples) -> np.ndarray:
    return samples.gravity[:, axis - 1:axis]


def _gravity_variable(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    return f"gravity torque on A{axis} (N m)", samples.gravity[:, axis - 1]


def compliance(axis: int) -> AngleTerm:
    """Gravity-induced deflection of one joint: ``k * gravity torque`` (k in rad per N m)."""
    key = f"compliance[A{axis}]"
    return AngleTerm(key, "compliance", (f"{key}.k",), (1e-5,),  # 20 arcsec at 10 N m
                     f"gravity compliance of joint A{axis}: the arm's own weight bends it by k x "
                     f"the gravity torque on A{axis} (torque from the URDF inertias)", axes=(axis,),
                     follows=(torque_variable(axis),), basis_of=partial(_gravity, axis),
                     variable_of=partial(_gravity_variable, axis))


class Compliance(Effect):
    """Gravity-induced joint deflection: k x gravity torque (URDF inertias)."""

    name = "compliance"
    description = "gravity-induced joint deflection: k x gravity torque (URDF inertias)"

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """One term per axis whose gravity torque varies."""
        return [compliance(a) for a in per_axis(arm) if varies(samples.gravity[:, a - 1], TORQUE_SPAN)]

    def term(self, key: str) -> Term | None:
        """``compliance[A<n>]``."""
        axis = axis_key("compliance", key)
        return None if axis is None else compliance(axis)

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """The gravity torque on every axis where it varies."""
        return [Variable(torque_variable(a), f"A{a}", *_gravity_variable(a, samples))
                for a in per_axis(arm) if varies(samples.gravity[:, a - 1], TORQUE_SPAN)]
