"""What a discovery run writes: ``discovery.json``, its figures and the final model as a CALDIR.

Figures: residuals against a named effect's variable before and after each step, the gap per
step, and, when the final residual is unexplained, the residual against the variable it follows.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aacmm_pin.analyses.discovery_results import Discovery, Step
from aacmm_pin.analyses.linear_scorer import FOLDS
from aacmm_pin.analyses.residual_scan import Scan
from aacmm_pin.data.logs import Campaign
from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.extras import require
from aacmm_pin.model.arm import Arm
from aacmm_pin.outputs.export import write_calibration_files
from aacmm_pin.outputs.figure_files import (
    SAMPLES,
    PanelFigure,
    figure_batch,
    fixed_figure,
    same_y,
    text_legend,
    write_png,
)
from aacmm_pin.outputs.plots import MODEL_COLOURS

if TYPE_CHECKING:
    from matplotlib.figure import Figure


TICKS = 4
"""Most intervals between ticks on an axis of a discovery figure (``nbins`` of matplotlib's
``MaxNLocator``, :func:`~aacmm_pin.outputs.figure_files.write_png`): 2 to 5 labelled ticks at
"nice" steps (1, 2, 2.5 or 5 x 10^k), against matplotlib's default of up to 9 on a panel 3 in
long. Ticks (marks and labels, built and drawn) are most of a panel's drawing: the UR5 grid's
first step figure builds 34 ticks instead of 60 and takes about a fifth less CPU to build and
draw (418 against 546 ms, medians of 11 interleaved rounds on a loaded machine)."""


DPI = 120
"""Resolution of the discovery figures' PNG files, dots per inch (the package's other figures:
150). A step figure of two rows is 1512 x 792 pixels, a screen's width; its smallest text (7 pt)
12 pixels high. Against 150 dpi (0.64x the pixels to draw and compress), the UR5 grid's
figures take about 15 % less CPU (1.01 against 1.19 s, best of 7 interleaved rounds)."""


def _binned(x: np.ndarray, y: np.ndarray, bins: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Return bin centres and bin means of y over x.

    A bin with fewer than 3 samples has mean NaN: a gap in the line drawn through the means, not a
    segment across a range no sample visited.
    """
    values = np.unique(x)
    if values.size <= 3:  # a discrete variable (e.g. a direction of motion)
        return values, np.array([y[x == v].mean() for v in values])
    edges = np.linspace(x.min(), x.max(), bins + 1)
    which = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    count = np.bincount(which, minlength=bins)
    total = np.bincount(which, weights=y, minlength=bins)
    means = np.where(count >= 3, total / np.maximum(count, 1), np.nan)
    return 0.5 * (edges[:-1] + edges[1:]), means


SCALE_QUANTILE = 0.005
"""Share of a panel's residuals, at each end, that may lie off its scale: the y range is that of
the rest (with zero), so that a few samples whose angle residual is ill-conditioned (an
axis nearly through the stylus: a small lever turns microns into degrees) do not flatten the
others; the samples off scale are drawn at the edge and counted."""


def _robust_ylim(ax: Any, ys: list[np.ndarray]) -> None:
    """Limit ``ax``'s y axis to the central residuals; note how many samples lie beyond.

    The range is the :data:`SCALE_QUANTILE` to 1 - :data:`SCALE_QUANTILE` quantiles of all the
    panel's residuals ``ys`` (each (n,)), with zero, widened by 10 % of the span; it is applied
    only when the full range is more than twice that span (else matplotlib's own). A bin mean
    that a few such samples drag beyond leaves the panel at its edge.
    """
    y = np.concatenate(ys)
    y = y[np.isfinite(y)]
    if y.size < 20:
        return
    lo, hi = np.quantile(y, [SCALE_QUANTILE, 1.0 - SCALE_QUANTILE])
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    pad = 0.1 * (hi - lo) if hi > lo else 1.0
    lo, hi = lo - pad, hi + pad
    if y.max() - y.min() <= 2.0 * (hi - lo):
        return
    ax.set_ylim(lo, hi)
    off = int(np.sum((y < lo) | (y > hi)))
    ax.annotate(f"{off} off scale (triangles at the edge)", (0.99, 0.02),
                xycoords="axes fraction", ha="right", va="bottom", fontsize=7, color="0.3")


def _off_scale(ax: Any, x: np.ndarray, y: np.ndarray, colour: str) -> None:
    """Draw the samples beyond ``ax``'s y limits as triangles at the edge.

    ``x``, ``y``: the panel's samples, each shape (n,), in its units.
    """
    lo, hi = ax.get_ylim()
    for beyond, edge, marker in ((y > hi, hi, "^"), (y < lo, lo, "v")):
        if beyond.any():
            ax.plot(x[beyond], np.full(int(beyond.sum()), edge), marker, ms=4, color=colour,
                    clip_on=False, ls="none")


def step_figure(step: Step, k: int, path: str | Path, shared: PanelFigure | None = None) -> None:
    """Write the residuals against each named term's variable, before and after step ``k``.

    ``shared``: a figure whose panels the step figures of one discovery share (their set-up
    built once, :class:`~aacmm_pin.outputs.figure_files.PanelFigure`); None: a figure of its own.
    """
    write_png(_step_figure(step, k, shared), path, TICKS, DPI)


def _step_figure(step: Step, k: int, shared: PanelFigure | None = None) -> Figure:
    """Build the figure of :func:`step_figure`: one panel per named term (up to 3 per row).

    The panels are ``shared``'s (a new :class:`~aacmm_pin.outputs.figure_files.PanelFigure` if
    None).
    """
    views: list[dict[str, Any]] = step.views
    ncols = min(max(len(views), 1), 3)
    nrows = max(1, -(-len(views) // ncols))
    # at least 8.4 in wide: the title (left) and the legend (right) share the top margin
    fig, axes = (shared or PanelFigure()).panels(
        max(4.2 * ncols, 8.4), 0.6 + 3.0 * nrows, len(views), ncols,
        margins=(1.0, 0.15, 0.55, 0.6), gaps=(1.1, 0.8))
    series = (("before", MODEL_COLOURS[0]), ("after", MODEL_COLOURS[3]))
    for ax, view in zip(axes, views):  # every named term, one panel each
        x = np.asarray(view["x"], dtype=float)
        drawn = []
        for key, colour in series:
            y = np.asarray(view[key], dtype=float)
            ax.plot(x, y, ".", ms=2, alpha=0.35, color=colour)
            bx, by = _binned(x, y)
            ax.plot(bx, by, "-o", ms=3, color=colour)
            drawn.append((y, colour))
        ax.axhline(0.0, color="k", lw=0.6)
        _robust_ylim(ax, [y for y, _ in drawn])
        for y, colour in drawn:
            _off_scale(ax, x, y, colour)
        ax.set_xlabel(view["variable"])
        ax.set_ylabel(view["residual"])
        ax.set_title(view["term"], fontsize=9, y=1.0)  # at the top (no search for room)
    # one legend for every panel, in the top margin's right end: lines of text (a legend box
    # costs more than a panel's points); the title at its left, as a suptitle's (a figure text:
    # the panels' next figure removes it)
    width, height = fig.get_size_inches()
    text_legend(fig, [(SAMPLES["-o"], f"{key} (bin means)", colour) for key, colour in series],
                1.0 - 0.15 / width, 1.0 - 0.05 / height, height)
    fig.text(0.1 / width, 0.98, f"step {k}: {step.effect} {step.axes or ''} - held-out RMS "
             f"{step.heldout_rms_before * 1e6:.2f} -> {step.heldout_rms_after * 1e6:.2f} um",
             fontsize=10, ha="left", va="top")
    return fig


def held_out_text(inputs: tuple[str, ...]) -> str:
    """How the held-out RMS leaves data out, for a calibration's ``inputs`` (its data kinds).

    R-Test locations (SPATs) are left out one at a time; absolute points in
    :data:`~aacmm_pin.analyses.linear_scorer.FOLDS` folds of the samples (each instrument group
    kept in every fold).
    """
    spat, points = "spat" in inputs, "points" in inputs
    if points and not spat:
        return f"{FOLDS} folds of the points"
    return "leave one location out" + (f"; points in {FOLDS} folds" if points else "")


def group_text(inputs: tuple[str, ...]) -> str:
    """What the residual scan takes each sample's mean over, for a calibration's ``inputs``."""
    spat, points = "spat" in inputs, "points" in inputs
    if points and not spat:
        return "its instrument group's mean"
    return "its location's or group's mean" if points else "its location's mean"


def gap_figure(result: Discovery, path: str | Path) -> None:
    """Write the held-out RMS, fit RMS and length-bar errors of the start model and every step."""
    write_png(_gap_figure(result), path, TICKS, DPI)


def _gap_figure(result: Discovery) -> Figure:
    """Build the figure of :func:`gap_figure`."""
    title = "gap per step (stopped: " + "\n".join(textwrap.wrap(result.stopped_because, 90)) + ")"
    # the title's lines at 7 pt (0.12 in each), the rotated labels below
    fig, grid = fixed_figure(6.4, 3.6, margins=(0.6, 0.6, 0.75, 0.15 + 0.12 * (title.count("\n") + 1)))
    ax = grid[0, 0]
    labels = [f"start ({result.start})"] + [f"+{s.effect} {','.join(map(str, s.axes))}".strip()
                                            for s in result.steps]
    x = np.arange(len(labels))
    series: list[tuple[str, str, str, list[Any]]] = [  # style, label, colour, values (m)
        ("-o", f"held-out RMS ({held_out_text(result.calibration.inputs)})", MODEL_COLOURS[2],
         list(result.heldout_rms)), ("-s", "fit RMS", MODEL_COLOURS[3], list(result.fit_rms)),
        ("-^", "length-bar RMS", MODEL_COLOURS[4], list(result.bar_rms)),
        ("--^", "length-bar RMS inside the SPAT coverage", MODEL_COLOURS[4],
         list(result.bar_covered_rms))]
    drawn = [one for one in series if all(v is not None for v in one[3])]  # no bars: none of theirs
    for style, _, colour, values in drawn:
        ax.plot(x, np.array(values, dtype=float) * 1e6, style, color=colour,
                mfc="none" if style == "--^" else colour)
    entries = [(style, label, colour) for style, label, colour, _ in drawn]
    ax.axhline(result.noise * 1e6, color="k", ls=":", lw=0.8)
    entries.append((":", "noise (sigma)", "k"))
    if all(v is not None for v in result.bar_normalised):
        right = ax.twinx()
        right.plot(x, np.array(result.bar_normalised, dtype=float), "-D", ms=4, color=MODEL_COLOURS[1])
        right.set_ylabel("normalised length-bar error")
        right.set_ylim(0.0, None)
        entries.append(("-D", "length-bar error / its predicted uncertainty (right)", MODEL_COLOURS[1]))
    ax.set_xticks(x, labels, rotation=15, fontsize=8)
    ax.set_ylabel("um")
    ax.set_ylim(0.0, None)
    ax.set_title(title, fontsize=7, y=1.0)
    text_legend(ax, [(SAMPLES[style], label, colour) for style, label, colour in entries],
                0.985, 0.975, ax.get_position().height * fig.get_figheight(), backed=True)
    return fig


def unexplained_figure(scan: Scan, path: str | Path, inputs: tuple[str, ...] = ("spat",),
                       shared: PanelFigure | None = None) -> None:
    """Write the final residual (less each location's mean) against the variable it follows most.

    One panel per coordinate: the residual of every sample and its binned means, with the stated
    noise as a band; the variable is the scan's top structure (else its best-ranked variable).
    ``inputs``: the calibration's data kinds (its ``inputs``), which name what the mean is over
    (:func:`group_text`: an R-Test location, an instrument group of points). ``shared``: the
    step figures' :class:`~aacmm_pin.outputs.figure_files.PanelFigure` (its panels reused);
    None: a figure of its own.
    """
    write_png(_unexplained_figure(scan, inputs, shared), path, TICKS, DPI)


def _unexplained_figure(scan: Scan, inputs: tuple[str, ...], shared: PanelFigure | None = None
                        ) -> Figure:
    """Build the figure of :func:`unexplained_figure`: three panels in a row, one y range."""
    top = (scan.structure or scan.variables)[0]
    hint = "\n".join(textwrap.wrap(scan.hint(), 130))
    # the title's lines at 8 pt (0.14 in each) above the panels' titles
    fig, axes = (shared or PanelFigure()).panels(
        11.0, 3.4, 3, 3, margins=(0.75, 0.15, 0.55, 0.4 + 0.14 * (hint.count("\n") + 1)),
        gaps=(0.3, 0.0))
    x = np.asarray(top.values, dtype=float)
    noise = scan.noise * 1e6
    for c, ax in enumerate(axes):
        y = scan.residual[:, c] * 1e6
        ax.plot(x, y, ".", ms=2, alpha=0.35, color=MODEL_COLOURS[0])
        bx, by = _binned(x, y)
        ax.plot(bx, by, "-o", ms=3, color=MODEL_COLOURS[3])
        ax.axhspan(-noise, noise, color="0.85", zorder=0)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xlabel(top.label or top.variable)
        ax.set_title(f"{'xyz'[c]} residual", fontsize=9, y=1.0)
    same_y(axes)  # as sharey: one scale, its numbers on the first panel
    axes[0].set_ylabel(f"residual less {group_text(inputs)} (um)")
    text_legend(axes[0], [(SAMPLES["-o"], "bin means", MODEL_COLOURS[3]),
                          (SAMPLES["span"], "stated noise (+- sigma)", "0.85")],
                0.985, 0.975, axes[0].get_position().height * fig.get_figheight(), backed=True)
    fig.text(0.5, 0.98, hint, fontsize=8, ha="center", va="top")  # a suptitle's place
    return fig


def write_discovery(result: Discovery, arm: Arm, folder: str | Path, force: bool = False,
                    campaign: Campaign | None = None, figures: bool = True) -> Path:
    """Write ``discovery.json``, the figures and the final model as a CALDIR in ``folder``.

    Files: ``discovery.json``, ``discovery_gap.png``, ``discovery_step<k>.png`` (residuals against
    the named effect's variable before and after), ``discovery_unexplained.png`` (when the final
    residual is unexplained: against the variable it follows most), and the CALDIR files of
    :func:`aacmm_pin.write_calibration` (``parameters.json`` with the extensions, ...; the
    URDF-alone loss over ``campaign``'s poses, the campaign discovered on). The folder is written
    whole (:func:`~aacmm_pin.data.output_folder.output_folder`). ``figures=False`` leaves the PNG
    files out (they need matplotlib, the ``figures`` extra).

    Raises:
        MissingExtraError: if ``figures`` and matplotlib is not installed (checked first).
        OutputExistsError: if ``folder`` holds files and not ``force``.
    """
    if figures:
        require("figures", "write_discovery")
    with output_folder(folder, force) as tmp:
        write_calibration_files(result.calibration, arm, tmp, campaign=campaign)
        (tmp / "discovery.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
        if figures:
            _write_figures(result, tmp)
    return Path(folder)


def _write_figures(result: Discovery, folder: Path) -> None:
    """Write the PNG files of :func:`write_discovery` into ``folder``."""
    with figure_batch():
        gap_figure(result, folder / "discovery_gap.png")
        shared = PanelFigure()  # the step and unexplained figures' panels, built once
        for k, step in enumerate(result.steps, start=1):
            step_figure(step, k, folder / f"discovery_step{k}.png", shared)
        if result.scan is not None and result.scan.unexplained and result.scan.variables:
            unexplained_figure(result.scan, folder / "discovery_unexplained.png",
                               result.calibration.inputs, shared)
