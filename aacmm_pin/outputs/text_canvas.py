"""An Agg canvas whose renderer draws each line of text as one bitmap, as matplotlib did up to 3.10.

matplotlib 3.11's Agg renderer draws text glyph by glyph from Python: each glyph is sized,
given a transform, rendered by FreeType and blended on its own (about 0.1 ms a glyph). Text is
most of drawing a discovery's figures (three quarters of redrawing a step figure's panels:
tick labels, axis labels, titles). :class:`StringRenderer` has FreeType lay out and render the
whole line in one call (``FT2Font.set_text``, ``draw_glyphs_to_bitmap``) and blends the bitmap
once, at a whole pixel, rotated in raster space when the text is: matplotlib 3.10's Agg text.
The glyphs are the same (same font, size, hinting, layout, kerning); a glyph may sit up to a
pixel from where 3.11 puts it (3.11 places each at a 64th of a pixel, this the line at a whole
pixel and its glyphs at whole pixels in it; ``tests/test_text_canvas.py``). A UR5 discovery's
figures take 0.77x the CPU without it (import excluded; median of 7 interleaved rounds).

:class:`StringCanvas` is the canvas of the package's figures
(:func:`~aacmm_pin.outputs.figure_files.new_figure`); other figures and matplotlib itself are
left as they are. Where matplotlib lacks what it uses (a version without
``FT2Font.draw_glyphs_to_bitmap``, or whose Agg renderer's text image call differs),
the text is drawn by matplotlib's own ``draw_text``, as it is from the first text whose private
calls raise ``AttributeError`` or ``TypeError`` on (a matplotlib whose internals changed).
Imported with matplotlib (the ``figures`` extra), by :mod:`~aacmm_pin.outputs.figure_files` only.
"""

from __future__ import annotations

from math import cos, radians, sin
from typing import Any, NamedTuple

import numpy as np
from matplotlib import rcParams
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg
from matplotlib.font_manager import findfont

try:  # internals of matplotlib's Agg text: a version without them draws text its own way
    from matplotlib.backends.backend_agg import get_hinting_flag
    from matplotlib.ft2font import FT2Font
except ImportError:  # pragma: no cover - another matplotlib
    get_hinting_flag = FT2Font = None  # type: ignore[assignment, misc]

WHOLE_LINES = FT2Font is not None and all(hasattr(FT2Font, name) for name in (
    "set_text", "draw_glyphs_to_bitmap", "get_image", "get_descent", "get_bitmap_offset",
    "get_width_height")) and hasattr(RendererAgg, "_prepare_font")
"""Whether this matplotlib's fonts lay out and render a whole line (else matplotlib's own
``draw_text`` draws every text)."""


class Line(NamedTuple):
    """A line of text laid out and rendered: its size (pixels) and its bitmap."""

    width: float
    """Advance of the unrotated line, pixels."""
    height: float
    """Height of the unrotated line, pixels."""
    descent: float
    """Depth below the baseline, pixels."""
    image: np.ndarray
    """Coverage of the line's box, shape (rows, columns), uint8."""
    offset: tuple[float, float]
    """The bitmap's offset from the line's origin, pixels."""


LINES: dict[tuple[Any, ...], Line] = {}
"""Lines laid out and rendered, by text, font properties, dpi, hinting, antialiasing, font
features and language: a figure's tick labels repeat ("0", "50", ...), and its texts are measured
before they are drawn, often by several renderers (one per figure size); each is laid out and
rendered once. Cleared when it holds :data:`MOST_LINES`."""
MOST_LINES = 2048
"""Most lines :data:`LINES` holds (about 1 kB each)."""


class StringRenderer(RendererAgg):
    """matplotlib's Agg renderer drawing each line of (non-math) text as one bitmap.

    Lines are laid out and rendered once (:data:`LINES`), for their size and their drawing.
    """

    def _line(self, s: str, prop: Any, antialiased: bool, mtext: Any = None) -> Line:
        """The line ``s`` in font ``prop`` at this renderer's dpi, from :data:`LINES` or made."""
        flags = get_hinting_flag()  # type: ignore[no-untyped-call]
        features = mtext.get_fontfeatures() if mtext is not None else None
        language = mtext.get_language() if mtext is not None else None
        key = (s, prop, self.dpi, flags, antialiased, features,  # a language may be a list
               language if language is None or isinstance(language, str) else tuple(language),
               findfont(prop), rcParams["text.hinting_factor"],  # the font file a family names
               rcParams["text.kerning_factor"])  # and the rcParams its layout reads, now
        line = LINES.get(key)
        if line is None:
            font = self._prepare_font(prop)  # type: ignore[no-untyped-call]
            font.set_text(s, 0.0, flags=flags, features=features, language=language)
            width, height = font.get_width_height()  # FreeType's 26.6 fixed point
            descent = font.get_descent()
            font.draw_glyphs_to_bitmap(antialiased=antialiased)
            dx, dy = font.get_bitmap_offset()
            line = Line(width / 64.0, height / 64.0, descent / 64.0, font.get_image(),
                        (dx / 64.0, dy / 64.0))
            if len(LINES) >= MOST_LINES:
                LINES.clear()
            LINES[(s, prop.copy()) + key[2:]] = line  # a copy: the Text's own may change
        return line

    def get_text_width_height_descent(self, s: str, prop: Any, ismath: bool | str
                                      ) -> tuple[float, float, float]:
        """Width, height and descent of ``s`` unrotated, pixels; math and TeX as matplotlib's."""
        if not ismath and WHOLE_LINES:
            try:
                line = self._line(s, prop, bool(rcParams["text.antialiased"]))
            except (AttributeError, TypeError):  # a matplotlib whose private calls changed
                _whole_lines_failed()
            else:
                return line.width, line.height, line.descent
        return super().get_text_width_height_descent(  # type: ignore[no-untyped-call, no-any-return]
            s, prop, ismath)

    def draw_text(self, gc: Any, x: float, y: float, s: str, prop: Any, angle: float,
                  ismath: bool | str = False, mtext: Any = None) -> None:
        """Draw the line ``s``, its baseline's left end at (``x``, ``y``) rotated ``angle`` degrees.

        ``x``, ``y``: pixels from the canvas's top left. Math text as matplotlib draws it.
        """
        if not ismath and WHOLE_LINES:
            try:
                self._draw_line(gc, x, y, s, prop, angle, mtext)
                return
            except (AttributeError, TypeError):  # a matplotlib whose private calls changed
                _whole_lines_failed()
        super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)  # type: ignore[no-untyped-call]

    def _draw_line(self, gc: Any, x: float, y: float, s: str, prop: Any, angle: float,
                   mtext: Any) -> None:
        line = self._line(s, prop, bool(gc.get_antialiased()), mtext)
        if line.image.size == 0:
            return
        # the bitmap's bottom left corner: the baseline lowered by the descent, along the angle
        left = round(x + line.offset[0] + line.descent * sin(radians(angle)))
        bottom = round(y + line.offset[1] + line.descent * cos(radians(angle)))
        self._renderer.draw_text_image(line.image, left, bottom + 1, angle, gc)


def _whole_lines_failed() -> None:
    """Draw every later text with matplotlib's own calls (this matplotlib's private ones differ)."""
    global WHOLE_LINES
    WHOLE_LINES = False


class StringCanvas(FigureCanvasAgg):
    """matplotlib's Agg canvas with a :class:`StringRenderer`."""

    def get_renderer(self) -> StringRenderer:
        """The canvas's renderer, made anew when the figure's pixel size or dpi changed."""
        width, height = self.get_width_height(physical=True)
        key = width, height, self.figure.dpi
        if getattr(self, "_lastKey", None) != key:
            self.renderer = StringRenderer(width, height, self.figure.dpi)  # type: ignore[no-untyped-call]
            self._lastKey = key
        return self.renderer  # type: ignore[no-any-return]
