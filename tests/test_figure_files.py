"""Tests of aacmm_pin.outputs.figure_files and in_view_ticks: the figures' one set-up, drawn cheaply.

Issue 28: a discovery's figures were 30 % of ``discover``'s CPU; they are written unhinted, with
ticks built only where they are drawn, and with the objects the process holds frozen while they
are written. The figures carry the same information (same pixels where only the ticks out of view
are left out). Issue 41: written from the Agg canvas as RGB (the pixels matplotlib writes) by
png_files (unfiltered rows: the same pixels, half Pillow's CPU), the step figures sharing one
figure's panels (the pixels of new panels).
"""

from __future__ import annotations

import gc
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from aacmm_pin.outputs import figure_files
from aacmm_pin.outputs.discovery_figures import TICKS, _step_figure, step_figure
from aacmm_pin.outputs.figure_files import DPI, PanelFigure, figure_batch, fixed_figure, write_png


def _step() -> Any:
    """A discovery step naming two terms, 300 samples each."""
    rng = np.random.default_rng(2)
    views = [{"term": f"encoder_harmonic[A{a}]", "variable": f"A{a} readout (deg)",
              "x": rng.uniform(-170.0, 170.0, 300), "residual": f"A{a} angle residual (arcsec)",
              "before": rng.normal(0.0, 10.0, 300), "after": rng.normal(0.0, 1.0, 300)}
             for a in (1, 2)]
    return SimpleNamespace(views=views, effect="encoder", axes=[1, 2],
                           heldout_rms_before=12e-6, heldout_rms_after=2e-6)


@pytest.mark.parametrize("nbins", ["auto", TICKS])
def test_step_figure_builds_ticks_only_in_the_view(tmp_path, nbins):
    """A discovery step figure builds no tick object outside its panels' views (they were a third
    of the ticks built, never drawn), and every tick drawn is still there; with at most TICKS
    intervals (the discovery figures') each axis still has 2 or more labelled ticks and fewer
    than matplotlib's default."""
    fig = _step_figure(_step(), 1)
    write_png(fig, tmp_path / "s.png", nbins)
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            low, high = sorted(axis.get_view_interval())
            locs = axis.get_majorticklocs()
            assert len(locs) >= (3 if nbins == "auto" else 2)  # the scale is still read
            assert len(locs) <= (9 if nbins == "auto" else TICKS + 1)
            assert np.all((locs >= low - 1e-9 * (high - low)) & (locs <= high + 1e-9 * (high - low)))
            assert len(axis.majorTicks) == len(locs)  # no tick built beyond those drawn


def test_in_view_ticks_leave_the_pixels_unchanged(tmp_path):
    """Leaving out the ticks outside the view changes no pixel of a discovery step figure."""
    from matplotlib.image import imread

    from aacmm_pin.outputs import in_view_ticks

    write_png(_step_figure(_step(), 1), tmp_path / "a.png")
    fig = _step_figure(_step(), 1)
    fig.set_dpi(DPI)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(in_view_ticks, "ticks_in_view", lambda _fig, _nbins: None)
        write_png(fig, tmp_path / "b.png")
    built = sum(len(ax.yaxis.majorTicks) for ax in fig.axes)
    locs = [(ax.yaxis.get_majorticklocs(), sorted(ax.get_ylim())) for ax in fig.axes]
    assert built > sum(int(np.sum((v >= low) & (v <= high))) for v, (low, high) in locs)
    assert np.array_equal(imread(tmp_path / "a.png"), imread(tmp_path / "b.png"))


def test_figures_are_written_unhinted_as_matplotlib_draws_them(tmp_path, monkeypatch):
    """write_png draws with unhinted text and writes, through png_files, the pixels matplotlib's
    own writer writes (RGB: the figure is opaque), at the dpi asked for, with matplotlib's
    metadata; matplotlib's settings and the figure's dpi are left as they were."""
    import matplotlib
    from matplotlib.image import imread
    from PIL import Image

    from aacmm_pin.outputs import png_files

    written: list[tuple[int, float]] = []
    write = png_files.write_png_file
    hinting: list[str] = []

    def keep(pixels: np.ndarray, path: Any, dpi: float, software: str = "") -> Any:
        written.append((pixels.shape[2], dpi))
        return write(pixels, path, dpi, software)

    before = matplotlib.rcParams["text.hinting"]
    fig = _step_figure(_step(), 1)
    draw = fig.canvas.draw

    def drawn() -> None:
        hinting.append(matplotlib.rcParams["text.hinting"])
        draw()

    own = fig.get_dpi()
    for dpi in (DPI, 120):
        monkeypatch.setattr(png_files, "write_png_file", keep)
        monkeypatch.setattr(fig.canvas, "draw", drawn)
        write_png(fig, tmp_path / f"ours{dpi}.png", dpi=dpi)
        monkeypatch.undo()
        assert fig.get_dpi() == own
        with matplotlib.rc_context({"text.hinting": figure_files.TEXT_HINTING}):
            fig.savefig(tmp_path / f"theirs{dpi}.png", format="png", dpi=dpi)
        ours, theirs = imread(tmp_path / f"ours{dpi}.png"), imread(tmp_path / f"theirs{dpi}.png")
        assert ours.shape[2] == 3 and np.all(theirs[..., 3] == 1.0)  # opaque: RGB, nothing lost
        assert np.array_equal(ours, theirs[..., :3])
        width, height = fig.get_size_inches()
        assert ours.shape[:2] == (round(height * dpi), round(width * dpi))
        with Image.open(tmp_path / f"ours{dpi}.png") as image, \
                Image.open(tmp_path / f"theirs{dpi}.png") as theirs_image:
            assert image.info["dpi"] == pytest.approx((dpi, dpi), abs=0.05)  # in px per m
            assert image.info["dpi"] == theirs_image.info["dpi"]
            assert image.info["Software"] == theirs_image.info["Software"]
    assert written == [(3, DPI), (3, 120)]
    assert hinting == [figure_files.TEXT_HINTING] * 2 and figure_files.TEXT_HINTING == "none"
    assert matplotlib.rcParams["text.hinting"] == before


def test_a_figure_with_transparent_pixels_keeps_its_alpha(tmp_path):
    """A figure whose face is transparent is written as RGBA: no pixel loses its alpha."""
    from matplotlib.image import imread

    fig, _ = fixed_figure(2.0, 1.5)
    fig.patch.set_alpha(0.0)
    write_png(fig, tmp_path / "t.png")
    image = imread(tmp_path / "t.png")
    assert image.shape[2] == 4 and image[..., 3].min() == 0.0


def test_step_figures_on_shared_panels_draw_the_pixels_of_new_ones(tmp_path):
    """Issue 41: the step figures of a discovery share one figure's panels (built once, moved to
    each layout, emptied); each PNG is the one a figure of its own writes, pixel for pixel, in
    either order (more panels after fewer and fewer after more, another grid shape), including
    a panel's limits set by the robust scale (off-scale samples) and then left to follow its
    data again."""
    from matplotlib.image import imread

    wild = _step()
    wild.views[0]["before"] = np.r_[np.random.default_rng(5).normal(0.0, 5.0, 297), 2e4, -2e4, 9e3]
    six = _step()
    six.views = [dict(six.views[k % 2], term=f"t{k}") for k in range(6)]
    one = _step()
    one.views = one.views[:1]
    steps = [wild, six, one, _step(), six]
    shared = PanelFigure()
    for k, step in enumerate(steps, start=1):
        step_figure(step, k, tmp_path / f"shared{k}.png", shared)
        step_figure(step, k, tmp_path / f"own{k}.png")
        assert np.array_equal(imread(tmp_path / f"shared{k}.png"), imread(tmp_path / f"own{k}.png")), k
    assert len(shared.axes) == 6  # built once: as many panels as the largest step's
    assert sum(ax.get_visible() for ax in shared.axes) == 6


def _scan(scale: float) -> Any:
    """A residual scan of 300 samples whose top variable is time, residuals ``scale`` m."""
    rng = np.random.default_rng(3)
    top = SimpleNamespace(values=np.arange(300.0), label="time (s)", variable="time")
    return SimpleNamespace(structure=[top], variables=[top], noise=0.3 * scale,
                           residual=rng.normal(0.0, scale, (300, 3)) * [1.0, 3.0, 0.5],
                           hint=lambda: "the residual follows time")


def test_unexplained_figures_on_shared_panels_draw_the_pixels_of_their_own(tmp_path):
    """Issue 41: the unexplained figure is drawn on the step figures' panels (their set-up built
    once): its PNG is the one a figure of its own writes, pixel for pixel, whose one y range and
    hidden inner y tick labels are sharey's; a step figure drawn on the panels after it (tick
    labels and offset text back on the inner panels) is a new figure's too."""
    from matplotlib.image import imread

    from aacmm_pin.outputs.discovery_figures import _unexplained_figure, unexplained_figure

    six = _step()
    six.views = [dict(six.views[k % 2], term=f"t{k}") for k in range(6)]
    shared = PanelFigure()
    for k, (kind, item) in enumerate([("scan", _scan(1e-6)), ("step", six), ("scan", _scan(1e-9)),
                                      ("step", _step())]):
        if kind == "scan":
            unexplained_figure(item, tmp_path / f"shared{k}.png", shared=shared)
            unexplained_figure(item, tmp_path / f"own{k}.png")
        else:
            step_figure(item, k, tmp_path / f"shared{k}.png", shared)
            step_figure(item, k, tmp_path / f"own{k}.png")
        assert np.array_equal(imread(tmp_path / f"shared{k}.png"), imread(tmp_path / f"own{k}.png")), k
    fig = _unexplained_figure(_scan(1e-6), ("spat",))
    fig.canvas.draw()
    first, *inner = fig.axes
    assert all(ax.get_ylim() == first.get_ylim() for ax in inner)  # one scale
    residual = _scan(1e-6).residual * 1e6  # um; y's spread 6x z's: every panel's on one scale
    low, high = first.get_ylim()
    assert low < residual.min() and high > residual.max()
    assert high - low < 1.2 * (residual.max() - residual.min())  # matplotlib's margins
    assert any(t.get_visible() and t.get_text() for t in first.get_yticklabels())
    assert not any(t.get_visible() and t.get_text() for ax in inner for t in ax.get_yticklabels())


def test_panel_boxes_match_fixed_figures_grid():
    """PanelFigure's layout is fixed_figure's: the same panel positions for the same margins."""
    fig, grid = fixed_figure(12.6, 6.6, 2, 3, margins=(1.0, 0.15, 0.55, 0.6), gaps=(1.1, 0.8))
    boxes = figure_files.panel_boxes(12.6, 6.6, 6, 3, (1.0, 0.15, 0.55, 0.6), (1.1, 0.8))
    for ax, box in zip(grid.ravel(), boxes):
        assert np.allclose(ax.get_position().bounds, box, atol=1e-12)


def _in_generations() -> set[int]:
    """ids of the objects the collector traverses (a frozen object is in none of its generations).

    Asked per object and not by ``gc.get_freeze_count()``: a frozen object that dies (e.g. in
    another thread, such as a test runner's) leaves the count, so the count can fall between reads.
    """
    return {id(obj) for obj in gc.get_objects()}


def test_figure_batch_freezes_what_the_process_holds_and_returns_it():
    """Inside a batch the objects made before (and matplotlib's) are frozen, out of the
    collector's traversals; after it nothing is left frozen, and a batch in a batch does nothing."""
    assert gc.get_freeze_count() == 0
    held = [[k] for k in range(1000)]  # objects made before the batch
    with figure_batch():
        traversed = _in_generations()
        assert not any(id(obj) in traversed for obj in held)
        made_inside = [[k] for k in range(1000)]
        with figure_batch():
            traversed = _in_generations()
            assert all(id(obj) in traversed for obj in made_inside)  # not frozen by the inner one
        fig, _ = fixed_figure(3.0, 2.0)
        assert gc.is_tracked(fig) and id(fig) in _in_generations()  # not frozen: collected
    assert gc.get_freeze_count() == 0
    traversed = _in_generations()
    assert all(id(obj) in traversed for obj in held)
    assert gc.isenabled()


def test_figure_batch_unfreezes_after_an_error():
    """A figure that fails leaves nothing frozen."""
    with pytest.raises(ValueError), figure_batch():
        raise ValueError("a figure failed")
    assert gc.get_freeze_count() == 0
