r"""Coupled joints as the files state them: a joint whose angle follows other joints' angles.

A coupled (passive) joint c has no encoder: its angle is a linear function of independent axes,

.. math:: q_c = \sum_i a_i \, q_i + b

(rad). A URDF ``<mimic joint="J" multiplier="a" offset="b"/>`` states one term; the ``couplings``
block of the arm's sizes file (:mod:`aacmm_pin.model.sizes`) states any sum::

    "couplings": {"T4": {"of": {"T2": -1.0, "T3": -1.0}, "offset": 0.0}}

(joint names; coefficients dimensionless, offset in rad). The arm
(:attr:`aacmm_pin.model.arm.Arm.couplings`) checks the names against its axes; the readers are told
the result per axis (:class:`AxisCoupling`, 0-based axis indices) and fill a coupled axis' readout
column where the file has none, or check the one it has (:func:`fill_or_check`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Coupling:
    """One coupled joint by names: ``joint = sum(coefficient * other) + offset`` (rad)."""

    joint: str
    """The coupled joint's name."""
    terms: tuple[tuple[str, float], ...]
    """(independent joint name, coefficient) of each term."""
    offset: float
    """Constant term b, rad."""
    source: str
    """Where it is stated (a URDF line or the sizes file), for messages."""

    def formula(self) -> str:
        """Return the coupling as text, angles in degrees (``T4 = -T2 - T3``)."""
        return formula(self.joint, self.terms, self.offset)


def formula(joint: str, terms: Sequence[tuple[str, float]], offset: float) -> str:
    """Return ``joint = a1 J1 + a2 J2 + b deg`` as text (unit coefficients without a number)."""
    parts = []
    for k, (name, a) in enumerate(terms):
        sign = "-" if a < 0 else "+" if k else ""
        mag = "" if math.isclose(abs(a), 1.0) else f"{abs(a):g} "
        parts.append(f"{sign}{mag}{name}" if not k else f" {sign} {mag}{name}")
    if offset:
        parts.append(f" {'-' if offset < 0 else '+'} {abs(math.degrees(offset)):g} deg")
    return f"{joint} = {''.join(parts) or '0'}"


@dataclass(frozen=True)
class AxisCoupling:
    """A coupled axis as the readers see it: axis indices instead of names."""

    axis: int
    """The coupled axis, 0-based (readout column ``q<axis + 1>_deg``)."""
    terms: tuple[tuple[int, float], ...]
    """(independent axis, 0-based; coefficient) of each term."""
    tolerance: float
    """Largest difference, rad, between a readout column given for it and the coupling of the
    other columns (the arm's plausible angle errors, :attr:`aacmm_pin.model.arm.Arm.axis_couplings`)."""
    coupling: Coupling
    """The coupling by names (its offset, rad, and its formula)."""

    def values(self, q: np.ndarray) -> np.ndarray:
        """Return the coupled angle for readouts q (N, n_axes), rad, shape (N,)."""
        out = np.full(q.shape[0], self.coupling.offset)
        for axis, a in self.terms:
            out = out + a * q[:, axis]
        return out


def fill_coupled(q: np.ndarray, couplings: Sequence[AxisCoupling]) -> np.ndarray:
    """Return readouts (N, n_axes), rad, with every coupled column set by its coupling (a copy)."""
    out = np.array(q, dtype=float, copy=True)
    for c in couplings:
        out[:, c.axis] = c.values(out)
    return out


def fill_or_check(cols: dict[str, list[Any]], q_columns: Sequence[str], lines: Sequence[int],
                  couplings: Sequence[AxisCoupling], add: Callable[..., None]) -> None:
    """Fill a table's missing coupled readout columns, or check the ones it has (degrees).

    A missing column is computed row by row (None where a cell it needs is bad). A column that
    is there is compared with the coupling of the others; rows beyond the coupling's tolerance are
    reported once, at the first such row, with their count and the largest difference.

    Args:
        cols: the table's parsed cells by column, in degrees (None: a bad cell); edited.
        q_columns: the readout columns in axis order.
        lines: the file line of each row.
        couplings: the arm's coupled axes.
        add: the file's problem log's ``add(line, column, reason)``.
    """
    for c in couplings:
        if c.axis >= len(q_columns):
            continue
        name = q_columns[c.axis]
        if any(q_columns[i] not in cols for i, _ in c.terms):
            continue
        sources = [(a, cols[q_columns[i]]) for i, a in c.terms]
        value = [None if any(s[r] is None for _, s in sources) else
                 math.degrees(c.coupling.offset) + sum(a * s[r] for a, s in sources)
                 for r in range(len(lines))]
        if name not in cols:
            cols[name] = value
            continue
        given = cols[name]
        tol = math.degrees(c.tolerance)
        off = [(r, abs(g - v)) for r, (g, v) in enumerate(zip(given, value))
               if g is not None and v is not None and abs(g - v) > tol]
        if off:
            worst = max(d for _, d in off)
            add(lines[off[0][0]], name, f"disagrees with the coupling {c.coupling.formula()} on {len(off)} "
                                        f"rows (up to {worst:.4g} deg, more than {tol:.3g} deg): a "
                                        "coupled joint needs no readout column; drop it, or fix "
                                        "the coupling (aacmm-pin axes ARM shows it)")
