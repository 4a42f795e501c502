"""A tick locator that places matplotlib's default ticks only where they are drawn: in the view.

matplotlib's default ``AutoLocator`` returns a tick beyond each end of the view, and the axis
builds a tick (two marks, a grid line and two labels) for every location it returns before
dropping those outside the view at draw time: on a discovery's figures, a third of the ticks built
are never drawn, and building them is a tenth of drawing the figures. :class:`InViewLocator`
returns the same locations, the ones outside the view left out, so the figure is the same.
:func:`ticks_in_view` can also ask for fewer ticks (``nbins``; the discovery figures'
:data:`~aacmm_pin.outputs.discovery_figures.TICKS`).
Imported by :func:`aacmm_pin.outputs.figure_files.write_png` only (it imports matplotlib).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import AutoLocator

CLOSE = 1e-10
"""Relative tolerance, of the view's span, of a tick at the view's end (matplotlib's own, with
which the axis drops ticks outside the view)."""


class InViewLocator(AutoLocator):
    """matplotlib's default locator (``AutoLocator``), without the locations outside the view.

    ``nbins``: most intervals between ticks; "auto" (matplotlib's default) follows the axis's
    length and font size.
    """

    def __init__(self, nbins: int | str = "auto") -> None:
        super().__init__()
        self.set_params(nbins=nbins)

    def __call__(self) -> Any:
        """The default locations, shape (n,), in data units, those outside the view dropped."""
        locs = np.asarray(super().__call__())
        low, high = sorted(self.axis.get_view_interval())  # type: ignore[union-attr]
        margin = CLOSE * (high - low)
        return locs[(locs >= low - margin) & (locs <= high + margin)]


def ticks_in_view(fig: Figure, nbins: int | str = "auto") -> None:
    """Give every axis of ``fig`` that has matplotlib's default locator an :class:`InViewLocator`.

    Axes with other locators (fixed ticks, log scales) are left as they are; a linear colour
    bar's axis has the default locator and gets one too (the same ticks drawn, with the default
    ``nbins``). ``nbins``: most intervals between ticks (4 on a discovery figure).
    """
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            if type(axis.get_major_locator()) is AutoLocator:
                axis.set_major_locator(InViewLocator(nbins))
