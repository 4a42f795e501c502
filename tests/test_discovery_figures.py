"""Tests of aacmm_pin.outputs.discovery_figures: the figure texts follow the campaign's kind."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from aacmm_pin.analyses.linear_scorer import FOLDS
from aacmm_pin.outputs.discovery_figures import _gap_figure, _unexplained_figure


def _texts(fig: Any) -> str:
    """Every label, legend entry and axis title of a figure, one string."""
    out = []
    for ax in fig.axes:
        out += [ax.get_ylabel(), ax.get_xlabel(), ax.get_title()]
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
