"""Tests of aacmm_pin.outputs.discovery_figures: the figure texts follow the campaign's kind."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from aacmm_pin.analyses.linear_scorer import FOLDS
from aacmm_pin.outputs.discovery_figures import _gap_figure, _step_figure, _unexplained_figure


def _texts(fig: Any) -> str:
    """Every label, legend entry (a legend box's or a text legend's) and title of a figure."""
    out = [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        out += [ax.get_ylabel(), ax.get_xlabel(), ax.get_title(), *(t.get_text() for t in ax.texts)]
        legend = ax.get_legend()
        if legend is not None:
            out += [t.get_text() for t in legend.get_texts()]
    return "\n".join(out)


def _discovery(inputs: tuple[str, ...]) -> Any:
    """A discovery result with a start model and no step (what the gap figure reads)."""
    return SimpleNamespace(start="dh", steps=[], heldout_rms=[2e-6], fit_rms=[1.5e-6],
                           bar_rms=[None], bar_covered_rms=[None], bar_normalised=[None],
                           noise=1e-6, stopped_because="no candidate shrinks the gap",
                           calibration=SimpleNamespace(inputs=inputs))


def _scan() -> Any:
    """A residual scan of 60 samples whose top variable is time."""
    rng = np.random.default_rng(0)
    top = SimpleNamespace(values=np.arange(60.0), label="time (s)", variable="time")
    return SimpleNamespace(structure=[top], variables=[top], noise=1e-6,
                           residual=rng.normal(0.0, 1e-6, (60, 3)), hint=lambda: "follows time")


@pytest.mark.parametrize("inputs, held, mean", [
    (("spat",), "leave one location out", "its location's mean"),
    (("points",), f"{FOLDS} folds of the points", "its instrument group's mean"),
    (("spat", "points"), f"leave one location out; points in {FOLDS} folds",
     "its location's or group's mean"),
])
def test_discovery_figure_texts_follow_the_campaign_kind(inputs, held, mean):
    """Issue 26 item 9: on point data the figures do not speak of R-Test locations: the held-out
    RMS is over folds of the points, the residual less its instrument group's mean."""
    gap = _texts(_gap_figure(_discovery(inputs)))
    scan = _texts(_unexplained_figure(_scan(), inputs))
    assert f"held-out RMS ({held})" in gap
    assert f"residual less {mean} (um)" in scan
    if "spat" not in inputs:
        assert "location" not in gap + scan


def _step(n_terms: int) -> Any:
    """A discovery step naming ``n_terms`` terms, 400 samples each, wide tick values."""
    rng = np.random.default_rng(1)
    views = [{"term": f"compliance[A{a}]", "variable": f"gravity torque on A{a} (N m)",
              "x": rng.normal(0.0, 100.0, 400), "residual": "residual along the term (um)",
              "before": rng.normal(0.0, 5000.0, 400), "after": rng.normal(0.0, 1.0, 400)}
             for a in range(1, n_terms + 1)]
    return SimpleNamespace(views=views, effect="compliance", axes=list(range(1, n_terms + 1)),
                           heldout_rms_before=3e-6, heldout_rms_after=2e-6)


def _long_discovery() -> Any:
    """A discovery with one step and a long stopping reason (a title of several lines)."""
    out = _discovery(("spat",))
    out.steps = [SimpleNamespace(effect="encoder", axes=[1, 2, 3, 4, 5, 6])]
    out.heldout_rms, out.fit_rms = [12e-6, 2e-6], [11e-6, 2e-6]
    out.bar_rms = out.bar_covered_rms = out.bar_normalised = [None, None]
    out.stopped_because = ("no candidate is significant against the noise (2.01 um): the best, "
                           "compliance[A2], changes the held-out RMS by -0.002 um, p = 0.09 "
                           "(needed < 3.1e-05), BIC gain -4.9; ") * 2
    return out


@pytest.mark.parametrize("build", [
    lambda: _step_figure(_step(6), 1), lambda: _step_figure(_step(2), 1),
    lambda: _step_figure(_step(1), 1), lambda: _gap_figure(_long_discovery()),
    lambda: _unexplained_figure(_scan(), ("spat",))], ids=["step6", "step2", "step1", "gap", "scan"])
def test_discovery_figures_fixed_layout_keeps_every_text_inside(build):
    """Issue 28: the discovery figures are laid out with fixed margins (no layout engine, which
    measured every label at each draw), and the margins hold them: every text (titles, labels,
    tick labels, legends) lies inside the figure and no two panels' boxes (with their labels)
    overlap."""
    fig = build()
    assert fig.get_layout_engine() is None
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    page = fig.bbox
    drawn = [ax.get_tightbbox(renderer) for ax in fig.axes]  # drawn ticks, labels and title
    drawn += [t.get_window_extent(renderer) for t in fig.texts if t.get_text()]  # suptitle
    drawn += [leg.get_window_extent(renderer) for leg in fig.legends]
    for box in drawn:
        assert box.x0 >= page.x0 - 0.5 and box.x1 <= page.x1 + 0.5, box
        assert box.y0 >= page.y0 - 0.5 and box.y1 <= page.y1 + 0.5, box
    tops = [t.get_window_extent(renderer) for t in fig.texts if t.get_text()]
    tops += [leg.get_window_extent(renderer) for leg in fig.legends]
    for i in range(len(tops)):  # the suptitle and the figure's legend side by side
        for j in range(i + 1, len(tops)):
            inter = tops[i].intersection(tops[i], tops[j])
            assert inter is None or inter.width <= 0.5 or inter.height <= 0.5
    panels = [ax for ax in fig.axes if ax.get_visible()]
    boxes = [ax.get_tightbbox(renderer) for ax in panels]
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            if panels[j] in panels[i].get_shared_x_axes().get_siblings(panels[i]) or \
                    panels[i].bbox.bounds == panels[j].bbox.bounds:  # a twin shares the panel
                continue
            inter = boxes[i].intersection(boxes[i], boxes[j])
            assert inter is None or inter.width <= 0.5 or inter.height <= 0.5, (i, j)


def test_step_panel_scale_follows_the_central_residuals_and_counts_the_rest():
    """A few ill-conditioned samples (angle residuals 1000x the rest: an axis nearly through the
    stylus) do not flatten a step panel: its y range is the central residuals' and the samples
    beyond are counted in a note; a panel without them keeps matplotlib's own range and no note."""
    step = _step(2)
    wild = step.views[0]
    wild["before"] = np.random.default_rng(2).normal(0.0, 5.0, 400)
    wild["before"][:3] = [-2e4, 1.5e4, 9e3]
    step.views[1]["before"] = np.random.default_rng(3).normal(0.0, 5.0, 400)
    fig = _step_figure(step, 1)
    ax_wild, ax_plain = fig.axes[:2]
    lo, hi = ax_wild.get_ylim()
    assert -100.0 < lo < -10.0 and 10.0 < hi < 100.0  # 5-sigma of the rest, padded: not 1e4
    notes = [t.get_text() for t in ax_wild.texts]
    assert notes == ["3 off scale (triangles at the edge)"]
    assert len(ax_plain.texts) == 0 and ax_plain.get_ylim()[1] - ax_plain.get_ylim()[0] < 100.0
