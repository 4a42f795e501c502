"""What the campaign readers and writers are told of an arm: its axis, tool and coupled-axis names.

The data layer never loads an arm: any object with ``axis_names`` and ``tool_names``
(:class:`ArmNames`, e.g. an :class:`~aacmm_pin.model.arm.Arm`) or the keywords ``axis_names=``
and ``tool_names=`` tell a reader what it needs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from aacmm_pin.data.couplings import AxisCoupling


class ArmNames(Protocol):
    """What a reader needs to know of an arm: its axis (joint) names and its tool names.

    An :class:`~aacmm_pin.model.arm.Arm` is one; so is any object with these two attributes.
    """

    @property
    def axis_names(self) -> Sequence[str]:
        """Joint name of every axis, in axis order (readout columns ``<joint name>_deg``)."""

    @property
    def tool_names(self) -> Sequence[str]:
        """Names of the tools, in tool order (``left`` for ``tool_left``; ``tool`` for one)."""


def given_names(arm: ArmNames | None, axis_names: Sequence[str] | None,
                tool_names: Sequence[str] | None) -> tuple[list[str] | None, list[str] | None]:
    """Return the axis and tool names a reader is told: the keywords', else the arm's."""
    axes = axis_names if axis_names is not None else None if arm is None else arm.axis_names
    tools = tool_names if tool_names is not None else None if arm is None else arm.tool_names
    return (None if axes is None else list(axes)), (None if tools is None else list(tools))


def couplings_of(arm: ArmNames | None) -> Sequence[AxisCoupling]:
    """Return the arm's coupled axes (its ``axis_couplings``, if it has any), for the readers."""
    return tuple(getattr(arm, "axis_couplings", ()))
