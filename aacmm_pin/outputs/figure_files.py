"""The figures' one set-up: a matplotlib Figure on its Agg canvas, drawn and written as PNG cheaply.

Every PNG figure of the package (:mod:`aacmm_pin.outputs.plots`,
:mod:`aacmm_pin.outputs.discovery_figures`) is a ``matplotlib.figure.Figure`` on its own
``FigureCanvasAgg`` (:func:`new_figure`, :func:`fixed_figure`, :class:`PanelFigure`: panels
shared by figures written one after another): pyplot is never imported, so no
GUI backend is looked for and no figure registry keeps figures alive. :func:`write_png` draws a
figure on its canvas with its text unhinted (:data:`TEXT_HINTING`) and writes its pixels
(:mod:`~aacmm_pin.outputs.png_files`: RGB when opaque); :func:`figure_batch` keeps the garbage
collector out of the way while a command writes its figures. matplotlib (the ``figures`` extra) is imported
inside the functions only; without it they raise :class:`~aacmm_pin.errors.MissingExtraError`.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from aacmm_pin.extras import require

if TYPE_CHECKING:
    from matplotlib.figure import Figure

DPI = 150
"""Resolution of the PNG files, dots per inch."""
TEXT_HINTING = "none"
"""matplotlib's ``text.hinting`` while a figure is drawn (:func:`write_png`): glyph
outlines as drawn, not snapped to the pixel grid (hinting changes a glyph's edge by less than a
pixel at 150 dpi); matplotlib renders text glyph by glyph, and unhinted text takes about a quarter
less of a discovery figure's drawing."""
SOFTWARE = "Matplotlib version{}, https://matplotlib.org/"
"""The ``Software`` text of the PNG files (matplotlib's own), with matplotlib's version."""
FIGURES = "writing figures"
"""What needs matplotlib, in the message of a missing ``figures`` extra."""


def new_figure(width_in: float, height_in: float,
               layout: Literal["constrained"] | None = "constrained") -> Figure:
    """Return an empty Figure on its own Agg canvas (no pyplot), constrained layout by default.

    The canvas is a :class:`~aacmm_pin.outputs.text_canvas.StringCanvas` (each line of text drawn
    as one bitmap: a quarter less CPU for a discovery's figures).

    Args:
        width_in: figure width, in.
        height_in: figure height, in.
        layout: ``"constrained"`` (margins measured at each draw) or None (the caller's fixed
            positions, :func:`fixed_figure`).

    Raises:
        MissingExtraError: if matplotlib (the ``figures`` extra) is not installed.
    """
    require("figures", FIGURES)
    from matplotlib.figure import Figure

    from aacmm_pin.outputs.text_canvas import StringCanvas

    fig = Figure(figsize=(width_in, height_in), layout=layout)
    StringCanvas(fig)
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


class PanelFigure:
    """One Figure on its Agg canvas whose panels are laid out anew for each figure written.

    A discovery writes a step figure per step (four on the UR5 grid), each a grid of panels with
    fixed margins. Building the panels (Axes, their axes and first ticks) and the ticks their
    first drawing adds cost about as much as drawing them again (the UR5 grid's first step
    figure, 5 panels: 81 and 77 ms, against 220 ms for a second drawing); :meth:`panels` hands
    the panels of the
    previous figure back, moved to the new layout and emptied of what was drawn on them (lines,
    texts, patches, collections, title, labels, the figure's legends and texts: a figure on
    them titles itself with ``fig.text``, not ``suptitle``), their ticks kept, and
    builds only the panels the previous figure lacked; panels beyond those asked for are hidden.
    A panel handed back draws the same pixels as a new one (``tests/test_figure_files.py``).
    The panels' axes must be left linear with their own limits (no shared or twin axes, no
    log scales, no fixed ticks): they are not reset; their locators are kept (the ``nbins`` the
    first :func:`write_png` of them gave).
    """

    def __init__(self) -> None:
        self.fig: Figure | None = None
        self.axes: list[Any] = []

    def panels(self, width_in: float, height_in: float, n: int, ncols: int,
               margins: tuple[float, float, float, float], gaps: tuple[float, float]
               ) -> tuple[Figure, list[Any]]:
        """The figure, ``width_in`` x ``height_in`` in, and ``n`` empty panels in rows of ``ncols``.

        ``margins`` (left, right, bottom, top) and ``gaps`` (between columns, rows), in, as
        :func:`fixed_figure`'s. Returns the figure and its ``n`` visible panels, row by row.
        """
        boxes = panel_boxes(width_in, height_in, n, ncols, margins, gaps)
        if self.fig is None:
            self.fig = new_figure(width_in, height_in, layout=None)
        else:
            self.fig.set_size_inches(width_in, height_in)
            for artist in [*self.fig.legends, *self.fig.texts]:
                artist.remove()
        for k, ax in enumerate(self.axes):
            ax.set_visible(k < n)
            if k < n:
                ax.set_position(boxes[k])
                _empty(ax)
        self.axes += [self.fig.add_axes(box) for box in boxes[len(self.axes):]]
        return self.fig, self.axes[:n]


LEGEND_LINE = 1.3
"""Spacing of a :func:`text_legend`'s lines, in font sizes."""


def text_legend(target: Any, entries: list[tuple[str, str, Any]], x: float, y: float,
                height_in: float, fontsize: float = 7.0, backed: bool = False) -> None:
    """Write a legend as lines of text, ending at ``x``, the first line's top at ``y``.

    matplotlib's legend box packs its entries' texts and handles anew at every draw: 10-25 ms a
    legend (a "best" place searched among the data: the most), against a few ms for a line of
    text. Each entry ``(sample, label, colour)`` is one line: ``label`` in black, right-aligned,
    then ``sample``, a few glyphs standing for the series' line and marker in its colour
    (:data:`SAMPLES`), centred in a column :data:`SAMPLE_EM` font sizes wide at the right end
    (matplotlib's ``markerfirst=False``).

    Args:
        target: a Figure (``x``, ``y`` in figure fractions) or an Axes (in axes fractions).
        entries: the lines, top first.
        x: right end of the lines, fraction of ``target``'s width.
        y: top of the first line, fraction of ``target``'s height.
        height_in: ``target``'s height, in (the lines' spacing in its fractions).
        fontsize: pt.
        backed: each text on a white box of 80 % opacity (a legend over data), else bare.
    """
    from matplotlib.transforms import offset_copy

    transform = target.transAxes if hasattr(target, "transAxes") else target.transSubfigure
    step = LEGEND_LINE * fontsize / 72.0 / height_in
    box = {"boxstyle": "square,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.8} if backed else None
    fig = target.get_figure()
    # the samples' column and the labels' right end, in points left of x
    at_sample = offset_copy(transform, fig, x=-0.5 * SAMPLE_EM * fontsize, units="points")
    at_label = offset_copy(transform, fig, x=-(SAMPLE_EM + 0.4) * fontsize, units="points")
    for k, (sample, label, colour) in enumerate(entries):
        baseline = y - k * step - fontsize / 72.0 / height_in
        target.text(x, baseline, sample, color=colour, fontsize=fontsize, ha="center",
                    va="baseline", transform=at_sample, bbox=box)
        target.text(x, baseline, label, color="black", fontsize=fontsize, ha="right",
                    va="baseline", transform=at_label, bbox=box)


SAMPLE_EM = 2.2
"""Width of a :func:`text_legend`'s column of samples, in font sizes (its widest sample, "─■─",
2.15)."""


SAMPLES = {"-o": "─●─", "-s": "─■─", "-^": "─▲─", "--^": "╌△╌", "-D": "─◆─", ":": "┈┈┈",
           "span": "■"}
"""A :func:`text_legend`'s samples of matplotlib's line styles and markers (DejaVu Sans glyphs):
a solid line with a circle, square, triangle, an open triangle on a dashed line, a diamond; a
dotted line; a shaded band (a square of its colour)."""


def panel_boxes(width_in: float, height_in: float, n: int, ncols: int,
                margins: tuple[float, float, float, float], gaps: tuple[float, float]
                ) -> list[tuple[float, float, float, float]]:
    """Positions of ``n`` panels in rows of ``ncols``, row by row from the top.

    The panels fill a ``width_in`` x ``height_in`` in figure less its ``margins`` and ``gaps``
    (in, as :func:`fixed_figure`'s). Returns (left, bottom, width, height) of each, in figure
    fractions.
    """
    left, right, bottom, top = margins
    nrows = max(1, -(-n // ncols))
    panel_w = (width_in - left - right - (ncols - 1) * gaps[0]) / ncols
    panel_h = (height_in - bottom - top - (nrows - 1) * gaps[1]) / nrows
    boxes = []
    for k in range(n):
        row, col = divmod(k, ncols)
        x0 = left + col * (panel_w + gaps[0])
        y0 = height_in - top - row * (panel_h + gaps[1]) - panel_h
        boxes.append((x0 / width_in, y0 / height_in, panel_w / width_in, panel_h / height_in))
    return boxes


def _empty(ax: Any) -> None:
    """Remove what was drawn on panel ``ax`` (artists, title, labels).

    Its limits follow its data again (autoscaled, as a new panel's).
    """
    for artist in [*ax.lines, *ax.texts, *ax.patches, *ax.collections]:
        artist.remove()
    ax.set_title("")
    ax.set_xlabel("")
    ax.set_ylabel("")
    if not ax.yaxis.offsetText.get_visible():  # an inner panel of same_y's
        ax.yaxis.set_tick_params(which="both", labelleft=True)
        ax.yaxis.offsetText.set_visible(True)
    ax.relim()
    ax.set_autoscale_on(True)


def same_y(axes: list[Any]) -> None:
    """Give a row of panels one y range, its tick labels on the first panel only: ``sharey``'s.

    The range is the one matplotlib's shared autoscaling gives (the panels' data together, widened
    by the first panel's y margin); the panels after the first lose their y tick labels and
    offset text (``label_outer``). Unlike ``sharey`` the panels stay independent, so that a
    :class:`PanelFigure` can hand them back: call after everything is drawn on them.
    """
    data = [v for ax in axes for v in ax.dataLim.intervaly if np.isfinite(v)]
    if not data:
        return
    low, high = axes[0].yaxis.get_major_locator().nonsingular(min(data), max(data))
    pad = axes[0].margins()[1] * (high - low)
    for k, ax in enumerate(axes):
        ax.set_ylim(low - pad, high + pad)
        if k:
            ax.yaxis.offsetText.set_visible(False)
            ax.yaxis.set_tick_params(which="both", labelleft=False)


def write_png(fig: Figure, path: str | Path, nbins: int | str = "auto", dpi: float = DPI) -> Path:
    """Draw ``fig`` at ``dpi`` (dots per inch; :data:`DPI`), text unhinted, and write it as PNG.

    The figure is drawn on its Agg canvas (text hinting :data:`TEXT_HINTING`) and its pixels
    written by :func:`~aacmm_pin.outputs.png_files.write_png_file` (unfiltered rows at zlib
    level :data:`~aacmm_pin.outputs.png_files.LEVEL`: half Pillow's CPU), with matplotlib's own
    metadata (software, resolution), parent folders created; an opaque figure (every pixel's
    alpha 255: a figure's default white face) as RGB, the same pixels as matplotlib's RGBA file
    with a quarter less to compress (:func:`png_pixels`).
    Ticks are built only where they are drawn, at most ``nbins`` intervals per axis
    (:func:`~aacmm_pin.outputs.in_view_ticks.ticks_in_view`). The figure's own dpi is restored
    after. Returns ``path`` as a Path.
    """
    require("figures", FIGURES)
    import matplotlib

    from aacmm_pin.outputs.in_view_ticks import ticks_in_view
    from aacmm_pin.outputs.png_files import write_png_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ticks_in_view(fig, nbins)
    own = fig.get_dpi()
    fig.set_dpi(dpi)
    try:
        with matplotlib.rc_context({"text.hinting": TEXT_HINTING}):
            fig.canvas.draw()
        write_png_file(png_pixels(fig), path, dpi, SOFTWARE.format(matplotlib.__version__))
    finally:
        fig.set_dpi(own)
    return path


def png_pixels(fig: Figure) -> np.ndarray:
    """The pixels of ``fig``'s drawn Agg canvas, shape (height, width, 3 or 4), uint8.

    RGB (a view of the canvas's RGBA buffer) when every pixel is opaque (a figure's default face;
    the same colours as matplotlib's RGBA file), RGBA else; at the figure's dpi.
    """
    import numpy as np

    rgba = np.asarray(fig.canvas.buffer_rgba())  # type: ignore[attr-defined]  # (h, w, 4) uint8
    return rgba[..., :3] if rgba[..., 3].min() == 255 else rgba


@contextmanager
def figure_batch() -> Iterator[None]:
    """Write figures without the garbage collector traversing what the process already holds.

    Importing matplotlib and drawing a figure create some 10^5 objects; the collections they
    trigger also traverse every object made before (a discovery holds about 10^5 more) and
    matplotlib's modules: on the sample campaign, 0.07 s of its figures' CPU. ``gc.freeze()``
    sets the objects made before aside for the batch, matplotlib is imported and its modules'
    objects are set aside too, and ``gc.unfreeze()`` returns them all after (0.025 s left);
    the figures' own objects are collected as usual. Does nothing when objects are frozen already
    (a batch in a batch, or the caller's own freeze: under ``aacmm-pin``, whose imports are
    frozen as they load, :mod:`aacmm_pin.cli._collector`, which then sets matplotlib's import and
    the objects made before it aside in the same way).
    """
    require("figures", FIGURES)
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        import matplotlib.figure  # noqa: F401  # what new_figure imports

        import aacmm_pin.outputs.text_canvas  # noqa: F401  # matplotlib's Agg backend

        gc.freeze()
        yield
    finally:
        gc.unfreeze()
