"""Text cells made safe for spreadsheets: :func:`neutralise_formula`, :func:`neutralise_formulas`.

A CSV cell that starts with ``=``, ``+``, ``-``, ``@``, a tab or a carriage return is run as a
formula by spreadsheets (CSV injection): a pose id ``=HYPERLINK(...)`` copied from a readouts file
into ``predict``'s output would be. The OWASP rule: such a cell is written with a single quote in
front, which spreadsheets show as text. A cell that is a plain number (``-1.5``, ``+2e-3``) is no
formula and stays as it is: numeric columns are untouched.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
"""First characters that make a spreadsheet read a cell as a formula (OWASP, CSV injection)."""

_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
"""A plain decimal number (no ``inf``, ``nan`` or expression)."""


def neutralise_formula(cell: str) -> str:
    """Return ``cell`` with a ``'`` in front if a spreadsheet would run it as a formula."""
    if cell.startswith(FORMULA_STARTS) and not _NUMBER.fullmatch(cell):
        return "'" + cell
    return cell


def neutralise_formulas(cells: Iterable[str]) -> list[str]:
    """Return every cell through :func:`neutralise_formula`."""
    return [neutralise_formula(c) for c in cells]
