"""The tool (stylus) vector: in every start model, so never a candidate of discovery."""

from __future__ import annotations

from typing import TYPE_CHECKING

from aacmm_pin.effects.base import Effect, Term

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.samples import Samples


class Tool(Effect):
    """Stylus/tool vector error (part of every start model)."""

    name = "tool"
    description = "stylus/tool vector error (part of every start model)"
    in_start = True

    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """None: every model has the tool."""
        return []

    def term(self, key: str) -> Term | None:
        """None: the tool is no extension."""
        return None
