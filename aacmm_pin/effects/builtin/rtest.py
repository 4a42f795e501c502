"""The stylus moving in its seat: the R-Test's measured displacement enters with a gain (Eq. 3)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.effects.base import Effect, MeasurementTerm, ModelSpec, Term, Variable

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples

VARIABLES = tuple(f"the R-Test displacement {c}" for c in "xyz")
"""The residual scan's names of the three displacement coordinates."""


def _displacement(samples: Samples) -> np.ndarray:
    out = np.zeros((samples.n, 3, 3))
    if samples.displacement is not None:
        for c in range(3):
            out[:, c, c] = -samples.displacement[:, c]  # residual = model - measured
    return out


def _displacement_variable(samples: Samples) -> tuple[str, np.ndarray]:
    disp = samples.displacement if samples.displacement is not None else np.zeros((samples.n, 3))
    return "R-Test displacement from its mean (um)", np.linalg.norm(disp, axis=1) * 1e6


class GainTerm(MeasurementTerm):
    """The R-Test displacement's gain per coordinate; in a model it is ``use_rtest``."""

    def in_model(self, model: ModelSpec) -> bool:
        """Whether the model adds the measured displacement."""
        return model.use_rtest

    def added_to(self, model: ModelSpec) -> ModelSpec:
        """The model adds the measured displacement (gain 1)."""
        return replace(model, use_rtest=True)


def rtest() -> GainTerm:
    """The stylus moving in its seat: the R-Test displacement enters with a gain per coordinate.

    With the displacement ignored (``use_rtest=False``) the gains come out near 1.
    """
    return GainTerm("rtest", "rtest", ("rtest.gain_x", "rtest.gain_y", "rtest.gain_z"),
                    (1.0, 1.0, 1.0), "the stylus sphere moves in its seat: the R-Test's measured "
                    "displacement must be added to the nest position (Eq. 3)", follows=VARIABLES,
                    basis_of=_displacement, variable_of=_displacement_variable)


def _moved(samples: Samples) -> bool:
    disp = samples.displacement
    return disp is not None and bool(np.abs(disp).max(initial=0.0) > 0)


class RTest(Effect):
    """The stylus moving in its seat (measured R-Test displacement)."""

    name = "rtest"
    description = "the stylus moving in its seat (measured R-Test displacement)"
    reads = ("dx_mm", "dy_mm", "dz_mm")

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """The gains, when the R-Test measured a displacement."""
        return [rtest()] if _moved(samples) else []

    def term(self, key: str) -> Term | None:
        """``rtest``."""
        return rtest() if key == "rtest" else None

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """Each displacement coordinate, tested on the other coordinates' residual (``own``)."""
        if not _moved(samples):
            return []
        assert samples.displacement is not None
        return [Variable(VARIABLES[c], name, f"R-Test displacement {name} (um)",
                         samples.displacement[:, c] * 1e6, "own") for c, name in enumerate("xyz")]

