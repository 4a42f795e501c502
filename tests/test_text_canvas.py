"""Tests of aacmm_pin.outputs.text_canvas: each line of text drawn as one bitmap, where matplotlib
draws it.

Issue 41: matplotlib 3.11 draws text glyph by glyph from Python, most of drawing a discovery's
figures; the package's canvas has FreeType render a whole line at once (matplotlib 3.10's Agg
text). The same glyphs must land where matplotlib puts them (within a pixel or two: 3.11 places
each glyph at a 64th of a pixel, this a whole line at a whole pixel), rotated text too; math text and a
matplotlib without the calls used are drawn by matplotlib itself, pixel for pixel.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from aacmm_pin.outputs import text_canvas
from aacmm_pin.outputs.figure_files import TEXT_HINTING, new_figure


def _ink(canvas: type, text: str, rotation: float, size: float) -> np.ndarray:
    """Darkness (0 white to 1 black), shape (rows, columns), of ``text`` drawn alone at 120 dpi
    on a figure with ``canvas``."""
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3.0, 3.0), dpi=120)
    canvas(fig)
    fig.text(0.5, 0.5, text, rotation=rotation, fontsize=size, ha="center", va="center")
    with matplotlib.rc_context({"text.hinting": TEXT_HINTING}):
        fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba(), dtype=float)
    return 1.0 - rgba[..., :3].mean(axis=2) / 255.0


def _box(ink: np.ndarray) -> tuple[int, int, int, int]:
    """First and last row and column holding ink (more than a tenth dark)."""
    rows, cols = np.nonzero(ink > 0.1)
    return rows.min(), rows.max(), cols.min(), cols.max()


@pytest.mark.parametrize("text, rotation, size", [
    ("A1 angle residual (arcsec)", 0.0, 10.0), ("−250", 0.0, 10.0),
    ("residual less its location's mean (um)", 90.0, 10.0), ("+encoder 1,2,3,4,5", 15.0, 8.0),
    ("step 1: encoder [1, 2, 3, 4, 5] - held-out RMS 65.40 -> 35.76 um", 0.0, 7.0),
    ("held-out RMS ─●─ ■ ┈┈┈", 0.0, 7.0), ("two lines\nof text", 0.0, 9.0)])
def test_whole_lines_land_where_matplotlib_draws_the_glyphs(text, rotation, size):
    """Each text drawn as whole lines covers matplotlib's own box within 2 pixels at each end
    (the line at a whole pixel and its glyphs at whole pixels in it, each up to a pixel from where
    matplotlib's 64ths put it), with the same ink (within 3 %), and is matplotlib's drawing moved
    by at most a pixel each way: the glyphs at the same places (the drawings correlate above
    0.85 moved by 0 or 1 pixel; moved by 3 pixels, below 0.6)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    ours = _ink(text_canvas.StringCanvas, text, rotation, size)
    theirs = _ink(FigureCanvasAgg, text, rotation, size)
    assert np.all(np.abs(np.subtract(_box(ours), _box(theirs))) <= 2), (_box(ours), _box(theirs))
    assert ours.sum() == pytest.approx(theirs.sum(), rel=0.03)

    def agreement(rows: int, columns: int) -> float:
        moved = np.roll(np.roll(ours, rows, axis=0), columns, axis=1)
        return float(np.corrcoef(moved.ravel(), theirs.ravel())[0, 1])

    best = max(agreement(r, c) for r in (-1, 0, 1) for c in (-1, 0, 1))
    assert best > 0.85
    assert max(agreement(3, 3), agreement(-3, -3)) < 0.6  # the comparison can tell


def test_math_text_and_a_matplotlib_without_whole_lines_are_drawn_by_matplotlib(monkeypatch):
    """Math text goes to matplotlib's own drawing; so does every text where the font calls used
    are missing (WHOLE_LINES false): the pixels of matplotlib's canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    math = r"$\sigma_{xy}^2$ (um$^2$)"
    assert np.array_equal(_ink(text_canvas.StringCanvas, math, 0.0, 10.0),
                          _ink(FigureCanvasAgg, math, 0.0, 10.0))
    monkeypatch.setattr(text_canvas, "WHOLE_LINES", False)
    plain = "A1 angle residual (arcsec)"
    assert np.array_equal(_ink(text_canvas.StringCanvas, plain, 90.0, 10.0),
                          _ink(FigureCanvasAgg, plain, 90.0, 10.0))


@pytest.mark.parametrize("broken, error", [("_line", AttributeError), ("_draw_line", TypeError)])
def test_a_matplotlib_whose_private_calls_changed_draws_every_text_itself(monkeypatch, broken,
                                                                         error):
    """If the private calls raise (a matplotlib whose internals changed: FreeType's line calls
    gone, the renderer's image call taking other arguments), the text is drawn by matplotlib's own
    code, then and from then on: the pixels of matplotlib's canvas, no error."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    def changed(*args: Any, **kwargs: Any) -> None:
        raise error("a changed private call")

    monkeypatch.setattr(text_canvas, "WHOLE_LINES", True)
    monkeypatch.setattr(text_canvas.StringRenderer, broken, changed)
    text = "A1 angle residual (arcsec)"
    drawn = _ink(text_canvas.StringCanvas, text, 0.0, 10.0)
    assert text_canvas.WHOLE_LINES is False
    assert np.array_equal(drawn, _ink(FigureCanvasAgg, text, 0.0, 10.0))


def test_the_package_figures_draw_whole_lines_and_only_they():
    """new_figure's figures have the canvas; matplotlib's own canvas is left as it is."""
    from matplotlib.backends import backend_agg

    fig: Any = new_figure(2.0, 2.0)
    assert isinstance(fig.canvas, text_canvas.StringCanvas) and text_canvas.WHOLE_LINES
    fig.canvas.draw()
    assert isinstance(fig.canvas.get_renderer(), text_canvas.StringRenderer)
    assert backend_agg.FigureCanvasAgg.get_renderer is not text_canvas.StringCanvas.get_renderer
    assert backend_agg.RendererAgg.draw_text is not text_canvas.StringRenderer.draw_text


def test_lines_are_laid_out_once_and_drawn_the_same_from_the_store(monkeypatch):
    """A figure's lines are laid out and rendered once each (for their size and their drawing;
    its repeated tick labels once): the store holds fewer lines than the figure draws, a second
    drawing (every line from the store) has the same pixels, and so does one after the store is
    emptied and one from a store cleared when full."""
    from matplotlib.backends.backend_agg import RendererAgg

    from aacmm_pin.outputs.discovery_figures import _step_figure
    from tests.test_figure_files import _step

    drawn: list[str] = []
    draw_text = text_canvas.StringRenderer.draw_text

    def counted(self: Any, gc: Any, x: float, y: float, s: str, *args: Any, **kwargs: Any) -> None:
        drawn.append(s)
        draw_text(self, gc, x, y, s, *args, **kwargs)

    text_canvas.LINES.clear()
    monkeypatch.setattr(text_canvas.StringRenderer, "draw_text", counted)
    fig = _step_figure(_step(), 1)
    fig.canvas.draw()
    first = np.array(fig.canvas.buffer_rgba())
    assert len(drawn) > len(set(drawn)) and len(text_canvas.LINES) < len(drawn)
    assert set(drawn) <= {key[0] for key in text_canvas.LINES}
    fig.canvas.draw()
    assert np.array_equal(np.asarray(fig.canvas.buffer_rgba()), first)
    monkeypatch.setattr(text_canvas, "MOST_LINES", 3)  # cleared again and again while drawing
    text_canvas.LINES.clear()
    fig.canvas.draw()
    assert np.array_equal(np.asarray(fig.canvas.buffer_rgba()), first)
    assert len(text_canvas.LINES) <= 3
    assert RendererAgg.get_text_width_height_descent is not \
        text_canvas.StringRenderer.get_text_width_height_descent
