r"""aacmm-pin-stylustemp: a stylus that grows with its own temperature, a frame that moves.

A stylus warms in the operator's hand and grows along itself: its tip moves by
:math:`k \, (T_{probe} - 20\,^\circ C) \, R \, t`, with k its expansion coefficient (1/K), R the
flange's rotation and t the tool vector (flange to sphere centre). The temperature is the campaign
files' column ``temp_probe_c`` (deg C), which aacmm_pin has never heard of.

The change is a small motion of one frame of the arm, the tool's: a
:class:`~aacmm_pin.FrameTerm` whose twist, in the tool frame's own axes (those of the flange: the
tool vector is a translation), is :math:`k \, (T - 20) \, (t, 0)`. The package applies it in its
kinematics (identification, ``predict``, the runtime arm, inverse kinematics, the viewer) and
takes its Jacobian columns from the frame's; the plugin states only the basis. One term per tool,
``stylus_thermal[<tool link>]``, one parameter ``k``.

Installed, the entry point ``stylus_thermal = aacmm_pin_stylustemp:StylusThermal`` in the group
``aacmm_pin.effects`` registers it in every process; or pass this file with ``--effects-file``.
"""

from __future__ import annotations

import re
from functools import partial
from typing import Any

import numpy as np

from aacmm_pin import Effect, FrameTerm, Term, Variable

COLUMN = "temp_probe_c"
"""The per-sample column this plugin reads: the stylus temperature, deg C."""
REFERENCE_C = 20.0
"""Temperature at which the stylus has its calibrated length, deg C."""
SPAN_C = 0.5
"""A stylus temperature that spans less than this (deg C) cannot show the expansion."""
VARIABLE = "the stylus temperature"
"""The residual scan's name of the stylus temperature."""
PLAUSIBLE = 1e-5
"""Plausible size of k, 1/K (steel 11.5e-6, ceramic 8e-6, carbon fibre near 0): the prior's scale."""


def probe_temperature(samples: Any) -> np.ndarray | None:
    """Return the samples' stylus temperature, shape (N,), deg C, or None without the column."""
    try:
        return np.asarray(samples.column(COLUMN), dtype=float)
    except KeyError:
        return None


def _tool_vector(samples: Any, link: str) -> np.ndarray:
    """The tool vector of the tool whose frame is ``link``, in the flange's axes, m.

    The arm's own (nominal) one: a calibration folder's arm (its ``calibrated.urdf``) holds the
    calibrated tool, a tenth of a millimetre from the nominal one, which changes the expansion
    by about 1e-3 of itself (tens of nanometres at most).
    """
    arm = samples.arm
    return np.asarray(arm.nominal_tools[arm.tool_joints[arm.tool_links.index(link)]], dtype=float)


def _basis(link: str, samples: Any) -> np.ndarray:
    """d(tool frame twist)/dk = (T - 20) (t, 0), shape (N, 6, 1), m/K."""
    temp = probe_temperature(samples)
    if temp is None:
        raise KeyError(f"the term stylus_thermal[{link}] needs a {COLUMN} column")
    out = np.zeros((samples.n, 6, 1))
    out[:, :3, 0] = (temp - REFERENCE_C)[:, None] * _tool_vector(samples, link)
    return out


def _variable(samples: Any) -> tuple[str, np.ndarray]:
    """The stylus temperature (deg C), for figures."""
    temp = probe_temperature(samples)
    return "stylus temperature (deg C)", np.zeros(samples.n) if temp is None else temp


def stylus_thermal(link: str) -> Term:
    """The expansion of the stylus of the tool frame ``link`` (one parameter k, 1/K)."""
    key = f"stylus_thermal[{link}]"
    return FrameTerm(key, "stylus_thermal", (f"{key}.k",), (PLAUSIBLE,),
                     f"the stylus of {link} grows with its temperature: k ({COLUMN} - 20 deg C) "
                     "x the tool vector", follows=(VARIABLE,), frame=link,
                     basis_of=partial(_basis, link), variable_of=_variable)


class StylusThermal(Effect):
    """Thermal expansion of the stylus with its own temperature (column ``temp_probe_c``)."""

    name = "stylus_thermal"
    description = "thermal expansion of the stylus with its own temperature (temp_probe_c)"
    reads = (COLUMN,)

    def candidates(self, arm: Any, samples: Any) -> list[Term]:
        """One term per tool, where the stylus temperature varies."""
        temp = probe_temperature(samples)
        if temp is None or np.ptp(temp) <= SPAN_C:
            return []
        return [stylus_thermal(link) for link in arm.tool_links]

    def term(self, key: str) -> Term | None:
        """``stylus_thermal[<tool link>]``."""
        match = re.fullmatch(r"stylus_thermal\[(.+)\]", key)
        return None if match is None else stylus_thermal(match.group(1))

    def variables(self, arm: Any, samples: Any) -> list[Variable]:
        """The stylus temperature, where it varies."""
        temp = probe_temperature(samples)
        if temp is None or np.ptp(temp) <= SPAN_C:
            return []
        return [Variable(VARIABLE, "stylus", "stylus temperature (deg C)", temp)]
