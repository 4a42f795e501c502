"""Tests of aacmm_pin.outputs.figure_files and in_view_ticks: the figures' one set-up, drawn cheaply.

Issue 28: a discovery's figures were 30 % of ``discover``'s CPU; they are written unhinted, at
zlib level 3, with ticks built only where they are drawn, and with the objects the process holds
frozen while they are written. The figures carry the same information (same pixels where only the
ticks out of view are left out).
"""

from __future__ import annotations

import gc
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from aacmm_pin.outputs import figure_files
from aacmm_pin.outputs.discovery_figures import _step_figure, step_figure
from aacmm_pin.outputs.figure_files import DPI, figure_batch, fixed_figure, write_png


def _step() -> Any:
    """A discovery step naming two terms, 300 samples each."""
    rng = np.random.default_rng(2)
    views = [{"term": f"encoder_harmonic[A{a}]", "variable": f"A{a} readout (deg)",
              "x": rng.uniform(-170.0, 170.0, 300), "residual": f"A{a} angle residual (arcsec)",
              "before": rng.normal(0.0, 10.0, 300), "after": rng.normal(0.0, 1.0, 300)}
             for a in (1, 2)]
    return SimpleNamespace(views=views, effect="encoder", axes=[1, 2],
                           heldout_rms_before=12e-6, heldout_rms_after=2e-6)


def _drawn_figures(monkeypatch) -> list[Any]:
    """Collect the figures ``Figure.savefig`` writes (after they are drawn)."""
    from matplotlib.figure import Figure

    written: list[Any] = []
    save = Figure.savefig

    def keep(fig: Any, *args: Any, **kwargs: Any) -> None:
        import matplotlib

        save(fig, *args, **kwargs)
        written.append((fig, matplotlib.rcParams["text.hinting"], kwargs))

    monkeypatch.setattr(Figure, "savefig", keep)
    return written


def test_step_figure_builds_ticks_only_in_the_view(tmp_path, monkeypatch):
    """A discovery step figure builds no tick object outside its panels' views (they were a third
    of the ticks built, never drawn), and every tick drawn is still there."""
    written = _drawn_figures(monkeypatch)
    step_figure(_step(), 1, tmp_path / "s.png")
    (fig, _, _), = written
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            low, high = sorted(axis.get_view_interval())
            locs = axis.get_majorticklocs()
            assert len(locs) >= 3  # the scale is still read
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
        patch.setattr(in_view_ticks, "ticks_in_view", lambda _fig: None)
        write_png(fig, tmp_path / "b.png")
    built = sum(len(ax.yaxis.majorTicks) for ax in fig.axes)
    locs = [(ax.yaxis.get_majorticklocs(), sorted(ax.get_ylim())) for ax in fig.axes]
    assert built > sum(int(np.sum((v >= low) & (v <= high))) for v, (low, high) in locs)
    assert np.array_equal(imread(tmp_path / "a.png"), imread(tmp_path / "b.png"))


def test_figures_are_written_unhinted_at_a_fast_zlib_level(tmp_path, monkeypatch):
    """write_png draws with unhinted text and asks Pillow for PNG_LEVEL, and leaves
    matplotlib's settings as they were; the file is a PNG of the figure's size at DPI."""
    import matplotlib
    from matplotlib.image import imread

    written = _drawn_figures(monkeypatch)
    before = matplotlib.rcParams["text.hinting"]
    step_figure(_step(), 1, tmp_path / "s.png")
    (fig, hinting, kwargs), = written
    assert hinting == figure_files.TEXT_HINTING == "none"
    assert kwargs["pil_kwargs"] == {"compress_level": figure_files.PNG_LEVEL}
    assert matplotlib.rcParams["text.hinting"] == before
    width, height = fig.get_size_inches()
    assert imread(tmp_path / "s.png").shape[:2] == (round(height * DPI), round(width * DPI))


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
