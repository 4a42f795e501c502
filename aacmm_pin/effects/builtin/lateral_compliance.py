r"""Lateral compliance: a joint tilts about the axes perpendicular to its own by k x gravity moment.

A joint's bearings, and the link behind it, give way under the moment gravity loads them with: about
the joint's axis (:mod:`aacmm_pin.effects.builtin.compliance`) and about the two axes perpendicular to it,
which no encoder sees. With :math:`(\tau_x, \tau_y)` the gravity moment about the lateral axes
:math:`u_x, u_y` of joint n (:attr:`aacmm_pin.model.samples.Samples.lateral_gravity`, from the URDF
inertias by Pinocchio's RNEA), the joint tilts by :math:`(\delta_x, \delta_y) = (k_x \tau_x, k_y
\tau_y)` on its child side (a :class:`~aacmm_pin.effects.base.TiltTerm`).
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.effects.base import Effect, Term, TiltTerm, Variable, axis_key, per_axis, varies
from aacmm_pin.effects.builtin.compliance import TORQUE_SPAN

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

NAME = "lateral_compliance"
LATERAL = ("x", "y")
"""The two lateral axes of a joint: x and y of its basis (z is the joint axis)."""


def lateral_variable(axis: int, k: int) -> str:
    """Return the residual scan's name of the lateral gravity moment on an axis (k: 0 x, 1 y)."""
    return f"the lateral gravity torque on A{axis} ({LATERAL[k]})"


def _basis(axis: int, samples: Samples) -> np.ndarray:
    torque = samples.lateral_gravity[:, axis - 1, :]  # (N, 2)
    out = np.zeros((samples.n, 2, 2))
    out[:, 0, 0], out[:, 1, 1] = torque[:, 0], torque[:, 1]
    return out


def _variable(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    torque = samples.lateral_gravity[:, axis - 1, :]
    return f"lateral gravity torque on A{axis} (N m)", np.linalg.norm(torque, axis=1)


def _component(axis: int, k: int, samples: Samples) -> tuple[str, np.ndarray]:
    return (f"lateral gravity torque on A{axis} ({LATERAL[k]}) (N m)",
            samples.lateral_gravity[:, axis - 1, k])


def lateral_compliance(axis: int) -> TiltTerm:
    """Gravity-induced lateral tilt of one joint: ``(kx tau_x, ky tau_y)`` (k in rad per N m)."""
    key = f"{NAME}[A{axis}]"
    return TiltTerm(key, NAME, (f"{key}.kx", f"{key}.ky"), (1e-5, 1e-5),  # 20 arcsec at 10 N m
                    f"lateral compliance of joint A{axis}: the arm's own weight tilts it about "
                    f"the two axes perpendicular to A{axis} by k x the gravity moment about each "
                    f"(moments from the URDF inertias)", axes=(axis,),
                    follows=(lateral_variable(axis, 0), lateral_variable(axis, 1)),
                    basis_of=partial(_basis, axis), variable_of=partial(_variable, axis))


def _varying(samples: Samples, axis: int) -> list[int]:
    """Return the lateral components (0 x, 1 y) of the axis whose gravity moment varies."""
    return [k for k in range(2) if varies(samples.lateral_gravity[:, axis - 1, k], TORQUE_SPAN)]


class LateralCompliance(Effect):
    """Gravity-induced lateral joint tilt: k x gravity moment about each lateral axis."""

    name = NAME
    description = ("gravity-induced lateral joint tilt: k x gravity moment about the two axes "
                   "perpendicular to the joint's (URDF inertias)")
    by_default = False
    """Tried when named only: where a joint's lateral axis is parallel to the next joint's axis
    (an AACMM's vertical A1 before its horizontal A2), the moments about them are the same and the
    two effects nearly indistinguishable (see docs/discovery.md)."""

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """One term per axis whose lateral gravity moment varies."""
        return [lateral_compliance(a) for a in per_axis(arm) if _varying(samples, a)]

    def term(self, key: str) -> Term | None:
        """``lateral_compliance[A<n>]``."""
        axis = axis_key(NAME, key)
        return None if axis is None else lateral_compliance(axis)

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """Each lateral gravity moment component that varies."""
        return [Variable(lateral_variable(a, k), f"A{a}", *_component(a, k, samples))
                for a in per_axis(arm) for k in _varying(samples, a)]
