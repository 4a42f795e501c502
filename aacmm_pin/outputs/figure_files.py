"""The figures' one set-up: a matplotlib Figure on its Agg canvas, drawn and written as PNG cheaply.

Every PNG figure of the package (:mod:`aacmm_pin.outputs.plots`,
:mod:`aacmm_pin.outputs.discovery_figures`) is a ``matplotlib.figure.Figure`` on its own
``FigureCanvasAgg`` (:func:`new_figure`, :func:`fixed_figure`): pyplot is never imported, so no
GUI backend is looked for and no figure registry keeps figures alive. :func:`write_png` draws a
figure with its text unhinted (:data:`TEXT_HINTING`) and writes it through matplotlib's own PNG
writer (Pillow) at zlib level :data:`PNG_LEVEL`; :func:`figure_batch` keeps the garbage collector
out of the way while a command writes its figures. matplotlib (the ``figures`` extra) is imported
inside the functions only; without it they raise :class:`~aacmm_pin.errors.MissingExtraError`.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from aacmm_pin.extras import require

if TYPE_CHECKING:
    import numpy as np
    from matplotlib.figure import Figure

DPI = 150
"""Resolution of the PNG files, dots per inch."""
TEXT_HINTING = "none"
"""matplotlib's ``text.hinting`` while a figure is drawn (:func:`write_png`): glyph
outlines as drawn, not snapped to the pixel grid (hinting changes a glyph's edge by less than a
pixel at 150 dpi); matplotlib renders text glyph by glyph, and unhinted text takes about a quarter
less of a discovery figure's drawing."""
PNG_LEVEL = 3
"""zlib level of the PNG files (Pillow's ``compress_level``; matplotlib leaves Pillow's 6). The
file holds the same pixels; on a discovery step figure level 3 takes two thirds of level 6's CPU
(60 against 89 ms) for a file 6 % larger (334 against 314 kB)."""
FIGURES = "writing figures"
"""What needs matplotlib, in the message of a missing ``figures`` extra."""


def new_figure(width_in: float, height_in: float,
               layout: Literal["constrained"] | None = "constrained") -> Figure:
    """Return an empty Figure on its own Agg canvas (no pyplot), constrained layout by default.

    Args:
        width_in: figure width, in.
        height_in: figure height, in.
        layout: ``"constrained"`` (margins measured at each draw) or None (the caller's fixed
            positions, :func:`fixed_figure`).

    Raises:
        MissingExtraError: if matplotlib (the ``figures`` extra) is not installed.
    """
    require("figures", FIGURES)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout=layout)
    FigureCanvasAgg(fig)
    return fig


def fixed_figure(width_in: float, height_in: float, nrows: int = 1, ncols: int = 1,
                 margins: tuple[float, float, float, float] = (0.75, 0.2, 0.6, 0.5),
                 gaps: tuple[float, float] = (0.75, 0.85), **subplots: Any
                 ) -> tuple[Figure, np.ndarray]:
    """Return a Figure on its own Agg canvas with fixed margins, no layout engine, and its panels.

    Constrained layout measures every tick label and title at each draw (on a discovery step's
    six panels, 40 % of drawing the figure); fixed margins cost nothing at draw time.

    Args:
        width_in: figure width, in.
        height_in: figure height, in.
        nrows: rows of panels.
        ncols: columns of panels.
        margins: left, right, bottom and top margins, in (room for labels and titles).
        gaps: width and height of the gaps between panels, in.
        subplots: passed to ``Figure.subplots`` (``sharey``, ...).

    Returns:
        The figure and its panels, shape (nrows, ncols).
    """
    left, right, bottom, top = margins
    panel_w = (width_in - left - right - (ncols - 1) * gaps[0]) / ncols
    panel_h = (height_in - bottom - top - (nrows - 1) * gaps[1]) / nrows
    fig = new_figure(width_in, height_in, layout=None)
    axes = fig.subplots(nrows, ncols, squeeze=False, gridspec_kw={
        "left": left / width_in, "right": 1.0 - right / width_in, "bottom": bottom / height_in,
        "top": 1.0 - top / height_in, "wspace": gaps[0] / panel_w, "hspace": gaps[1] / panel_h},
        **subplots)
    return fig, axes


def write_png(fig: Figure, path: str | Path) -> Path:
    """Draw ``fig`` at :data:`DPI`, text unhinted (:data:`TEXT_HINTING`), and write it as PNG.

    ``fig.savefig`` (matplotlib's PNG writer, Pillow) to ``path`` at zlib level :data:`PNG_LEVEL`,
    parent folders created; ticks are built only where they are drawn
    (:func:`~aacmm_pin.outputs.in_view_ticks.ticks_in_view`). Returns ``path`` as a Path.
    """
    require("figures", FIGURES)
    import matplotlib

    from aacmm_pin.outputs.in_view_ticks import ticks_in_view

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ticks_in_view(fig)
    with matplotlib.rc_context({"text.hinting": TEXT_HINTING}):
        fig.savefig(path, format="png", dpi=DPI, pil_kwargs={"compress_level": PNG_LEVEL})
    return path


@contextmanager
def figure_batch() -> Iterator[None]:
    """Write figures without the garbage collector traversing what the process already holds.

    Importing matplotlib and drawing a figure create some 10^5 objects; the collections they
    trigger also traverse every object made before (a discovery holds about 10^5 more) and
    matplotlib's modules: on the sample campaign, 0.07 s of its figures' CPU. ``gc.freeze()``
    sets the objects made before aside for the batch, matplotlib is imported and its modules'
    objects are set aside too, and ``gc.unfreeze()`` returns them all after (0.025 s left);
    the figures' own objects are collected as usual. Does nothing when objects are frozen already
    (a batch in a batch, or the caller's own freeze).
    """
    require("figures", FIGURES)
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        import matplotlib.backends.backend_agg  # noqa: F401  # what new_figure imports
        import matplotlib.figure  # noqa: F401

        gc.freeze()
        yield
    finally:
        gc.unfreeze()
