"""Figures of a calibration as PNG files: the paper's Fig. 5 (R-Test), Fig. 6 (maps), Fig. 9 (bar).

Data come in SI (m, rad); the figures show display units (µm, arcsec, deg). matplotlib is imported
inside the functions only, and figures are built as ``matplotlib.figure.Figure`` on an Agg canvas,
so no pyplot state, GUI backend or open-figure registry is touched.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aacmm_pin.analyses.validation import ValidationResult
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.model.encoder_map import node_count
from aacmm_pin.outputs.figure_files import new_figure, write_png
from aacmm_pin.units import ARCSEC

if TYPE_CHECKING:
    from matplotlib.figure import Figure

UM_PER_M = 1e6
# Colour-blind-safe model colours (grey, then Okabe-Ito orange, vermillion, blue, green, purple, sky).
MODEL_COLOURS = ("#8c8c8c", "#e69f00", "#d55e00", "#0072b2", "#009e73", "#cc79a7", "#56b4e9")


def _save(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG to ``path`` (parent folders created), release it, return the path."""
    path = write_png(fig, path)
    fig.clear()
    return path


# --- Fig. 5: R-Test displacement during the SPAT -------------------------------------------------


def plot_rtest_displacement(campaign: Campaign, path: str | Path, location: int | None = None) -> Path:
    """Plot the sphere displacement measured by the R-Test during the SPAT at one location (Fig. 5).

    Left panel: dy vs dx in µm (equal aspect), samples joined in sample order and coloured by
    sample number, the largest XY displacement from the R-Test zero annotated. Right panel: dz vs
    sample number in µm.

    Args:
        campaign: a campaign with SPAT; uses ``spat.location``, shape (N,), and
            ``spat.displacement``, shape (N, 3), in m.
        path: PNG file to write.
        location: R-Test location to show; None picks the one with the largest XY displacement.

    Returns:
        ``path`` as a Path.

    Raises:
        ValueError: if the campaign has no SPAT (``campaign``) or ``location`` is not in it.
    """
    return _save(_rtest_displacement_figure(campaign, location), path)


def _rtest_displacement_figure(campaign: Campaign, location: int | None = None) -> Figure:
    """Build the figure of :func:`plot_rtest_displacement` (same arguments but ``path``)."""
    spat = campaign.spat
    if spat is None:
        raise ValueError("campaign: has no SPAT, nothing to plot")
    ids = campaign.location_ids
    xy_norm = np.hypot(spat.displacement[:, 0], spat.displacement[:, 1])
    if location is None:
        location = max(ids, key=lambda k: float(xy_norm[spat.location == k].max()))
    elif int(location) not in ids:
        raise ValueError(f"location: choose one of {list(ids)}, got {location}")
    d_um = spat.displacement[spat.location == int(location)] * UM_PER_M
    return _rtest_figure(d_um, int(location))


def _rtest_figure(d_um: np.ndarray, location: int) -> Figure:
    """Build the Fig. 5 figure from the displacements of one location, shape (N, 3), in µm."""
    from matplotlib.colors import Normalize

    n = len(d_um)
    sample = np.arange(1, n + 1)
    norm, cmap = Normalize(1, max(n, 2)), "viridis"
    fig = new_figure(10.0, 4.8)
    ax_xy, ax_z = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.15]})
    fig.suptitle(f"R-Test sphere displacement during the SPAT at location #{location}")

    # the postures are not a path: points only (colour: sample order), the zero on top of them
    points = ax_xy.scatter(d_um[:, 0], d_um[:, 1], c=sample, cmap=cmap, norm=norm, s=9, zorder=3)
    ax_xy.plot(0, 0, "+", color="white", ms=14, mew=3.2, zorder=4)
    ax_xy.plot(0, 0, "+", color="black", ms=12, mew=1.4, zorder=4.5)
    k = int(np.argmax(np.hypot(d_um[:, 0], d_um[:, 1])))
    r_max = float(np.hypot(d_um[k, 0], d_um[k, 1]))
    ax_xy.plot(d_um[k, 0], d_um[k, 1], "o", ms=11, mfc="none", mec="#d55e00", mew=1.6, zorder=5)
    # A square view centred on the zero: every sample lies within r_max of it, so the corner on the
    # side of the farthest sample holds no data and takes the label.
    half = 1.0 if r_max == 0 else 1.6 * r_max
    right, top = bool(d_um[k, 0] >= 0), bool(d_um[k, 1] >= 0)
    ax_xy.annotate(f"max |XY| {r_max:.1f} µm\n(sample {k + 1})", (d_um[k, 0], d_um[k, 1]),
                   xytext=(0.97 if right else 0.03, 0.97 if top else 0.03),
                   textcoords="axes fraction", ha="right" if right else "left",
                   va="top" if top else "bottom", color="#d55e00", fontsize="small", zorder=6,
                   arrowprops={"arrowstyle": "-", "color": "#d55e00", "lw": 0.8,
                               "shrinkB": 6})
    ax_xy.set_xlim(-half, half)
    ax_xy.set_ylim(-half, half)
    ax_xy.set_aspect("equal", adjustable="box")
    ax_xy.set_xlabel("dx (µm)")
    ax_xy.set_ylabel("dy (µm)")
    ax_xy.set_title("XY plane (+: R-Test zero)", fontsize="medium")
    ax_xy.grid(True, lw=0.4, alpha=0.5)

    ax_z.scatter(sample, d_um[:, 2], c=sample, cmap=cmap, norm=norm, s=9, zorder=3)
    ax_z.axhline(0.0, color="black", lw=0.6)
    ax_z.set_xlabel("sample")
    ax_z.set_ylabel("dz (µm)")
    ax_z.set_title("Z direction", fontsize="medium")
    ax_z.grid(True, lw=0.4, alpha=0.5)
    fig.colorbar(points, ax=[ax_xy, ax_z], label="sample", shrink=0.9)
    return fig


# --- Fig. 6: encoder error maps ------------------------------------------------------------------

MIN_SPAN_ARCSEC = 1.0
"""Smallest half-range of a Fig. 6 panel, arcsec: below it an axis shows noise, not an error."""


def _per_axis(name: str, table: Mapping[int, Any] | None, n: int, step_deg: float,
              dtype: type = float) -> dict[int, np.ndarray]:
    """Return ``table`` as axis -> array of shape (n,), raising ValueError naming ``name``."""
    out: dict[int, np.ndarray] = {}
    for axis, values in (table or {}).items():
        arr: np.ndarray = np.asarray(values, dtype=dtype)
        if arr.shape != (n,):
            raise ValueError(f"{name}: axis {axis} has shape {arr.shape}, but a map with step "
                             f"{step_deg:g} deg has {n} nodes")
        out[int(axis)] = arr
    return out


def _unreached_spans(reached: np.ndarray, step_deg: float) -> list[tuple[float, float]]:
    """Return the readout ranges (deg) of the runs of unreached nodes, each node +- step/2.

    ``reached``: per node from -180 deg, shape (n,), bool. A run across +-180 deg gives two spans.
    """
    x_deg = -180.0 + step_deg * np.arange(len(reached))
    spans: list[tuple[float, float]] = []
    for k in np.flatnonzero(~reached):
        low = -185.0 if k == 0 else x_deg[k] - step_deg / 2
        high = x_deg[k] + step_deg / 2
        if spans and abs(spans[-1][1] - low) < 1e-9:
            spans[-1] = (spans[-1][0], high)
        else:
            spans.append((low, high))
    if not reached[0]:  # node 0 (-180 deg) is also +180 deg: shade up to the edge there
        spans.append((180.0 - step_deg / 2 if reached[-1] else spans[-1][1], 185.0))
    return spans


def plot_encoder_maps(maps: dict[int, np.ndarray], path: str | Path, *, step_deg: float = 5.0,
                      identifiable: dict[int, np.ndarray] | None = None,
                      std: dict[int, np.ndarray] | None = None,
                      truth: dict[int, np.ndarray] | None = None,
                      axes: list[int] | None = None,
                      reached: dict[int, np.ndarray] | None = None) -> Path:
    """Plot identified angular position measurement errors vs nominal readout, one panel per axis.

    Paper Fig. 6: identified nodes as blue dots with k = 1 error bars; nodes not identifiable as
    hollow grey markers without error bar, counted in the panel's top-right note; the truth as a
    thin black line over every node (give it in the fit's gauge,
    :meth:`~aacmm_pin.fit.identification_result.Calibration.maps_in_gauge`). Where no posture's
    readout reached (``reached`` False) the range is shaded and no identified value is drawn:
    the fit holds those nodes at zero, which is no measurement. The optional tables may cover
    only some axes.

    Args:
        maps: axis number n -> identified error at the nodes, shape (360/step_deg,), in rad; node k
            sits at nominal readout -180 deg + k * step_deg.
        path: PNG file to write.
        step_deg: node spacing in deg; must divide 360.
        identifiable: axis -> per-node flag, shape (360/step_deg,), bool; False = not identifiable.
        std: axis -> standard uncertainty (k = 1) of each node, shape (360/step_deg,), in rad.
        truth: axis -> true error at the nodes, shape (360/step_deg,), in rad.
        axes: axes to show, one panel each, in this order; default: sorted keys of ``maps``.
        reached: axis -> per-node flag, shape (360/step_deg,), bool; False = no posture's
            readout reached the node (default: all reached).

    Returns:
        ``path`` as a Path.

    Raises:
        ValueError: naming the argument, if ``maps`` or ``axes`` is empty or ``axes`` names an axis
            missing from ``maps``, ``step_deg`` does not divide 360, or a table has the wrong shape.
    """
    fig = _encoder_map_figure(maps, step_deg=step_deg, identifiable=identifiable, std=std,
                              truth=truth, axes=axes, reached=reached)
    return _save(fig, path)


def _map_panel(ax: Any, axis: int, values: np.ndarray, flags: np.ndarray | None,
               std: np.ndarray | None, truth: np.ndarray | None, reached: np.ndarray | None,
               step_deg: float) -> np.ndarray | None:
    """Draw one axis' map into ``ax``; return the error bars drawn (arcsec), or None.

    ``values``, ``std``, ``truth``: the map's node values, their std and the true ones, rad,
    shape (n,); ``flags``, ``reached``: which nodes are identifiable and reached (None: all).
    """
    n = len(values)
    x_deg = -180.0 + step_deg * np.arange(n)
    y = values / ARCSEC
    hit = reached if reached is not None else np.ones(n, dtype=bool)
    ident = flags if flags is not None else np.ones(n, dtype=bool)
    ok = ident & hit
    lost = ~ident & hit  # reached, yet not determined
    err = std[ok] / ARCSEC if std is not None else None
    top = max(float(np.max(np.abs(y[hit]), initial=0.0)), MIN_SPAN_ARCSEC)
    if err is not None and err.size:
        top = max(top, float(np.max(np.abs(y[ok]) + err)))
    if truth is not None:
        t = np.where(np.abs(truth) / ARCSEC < 1e-6, 0.0, truth / ARCSEC)  # rounding
        top = max(top, float(np.max(np.abs(t))))
        ax.plot(np.append(x_deg, 180.0), np.append(t, t[0]), color="black", lw=0.8, zorder=2)
    for low, high in _unreached_spans(hit, step_deg):
        ax.axvspan(low, high, color="0.88", lw=0, zorder=0)
    ax.errorbar(x_deg[ok], y[ok], yerr=err, fmt="o", ms=2.5, color="#0072b2", ecolor="#0072b2",
                elinewidth=0.9, capsize=1.5, zorder=3)
    # at least +-MIN_SPAN_ARCSEC: an axis the data cannot see is flat, not magnified noise
    ax.set_ylim(-1.12 * top, 1.12 * top)
    ax.plot(x_deg[lost], y[lost], "o", ms=4.5, mfc="none", mec="0.55", mew=1.0, zorder=3)
    ax.axhline(0.0, color="0.3", lw=0.5, zorder=1)
    ax.set_title(f"A{axis}-axis", loc="left", fontsize="medium", fontweight="bold")
    if (~ok).any():
        away = "" if hit.all() else f" ({int((~hit).sum())} not reached)"
        ax.set_title(f"{int((~ok).sum())} of {n} nodes not identifiable{away}", loc="right",
                     fontsize="small", color="0.35")
    ax.set_xlim(-185.0, 185.0)
    ax.set_xticks(np.arange(-180, 181, 90))
    ax.tick_params(labelbottom=True)
    ax.grid(True, lw=0.4, alpha=0.5)
    return err


def _encoder_map_figure(maps: dict[int, np.ndarray], *, step_deg: float = 5.0,
                        identifiable: dict[int, np.ndarray] | None = None,
                        std: dict[int, np.ndarray] | None = None,
                        truth: dict[int, np.ndarray] | None = None,
                        axes: list[int] | None = None,
                        reached: dict[int, np.ndarray] | None = None) -> Figure:
    """Build the figure of :func:`plot_encoder_maps` (same arguments but ``path``)."""
    from matplotlib.artist import Artist
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if not maps:
        raise ValueError("maps: no encoder map given")
    try:
        n = node_count(step_deg)
    except ValueError:
        raise ValueError(f"step_deg: must divide 360 deg, got {step_deg}") from None
    values = _per_axis("maps", maps, n, step_deg)
    flags = _per_axis("identifiable", identifiable, n, step_deg, bool)
    sigma = _per_axis("std", std, n, step_deg)
    true = _per_axis("truth", truth, n, step_deg)
    seen = _per_axis("reached", reached, n, step_deg, bool)
    shown = sorted(values) if axes is None else [int(a) for a in axes]
    if not shown or any(a not in values for a in shown):
        raise ValueError(f"axes: choose one or more of {sorted(values)}, got {axes}")

    ncols = 1 if len(shown) == 1 else 2
    nrows = math.ceil(len(shown) / ncols)
    fig = new_figure(5.0 * ncols, 1.0 + 2.5 * nrows)
    grid = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False)).ravel()
    for ax in grid[len(shown):]:
        ax.remove()
    errs: list[np.ndarray] = []
    for ax, axis in zip(grid, shown):
        err = _map_panel(ax, axis, values[axis], flags.get(axis), sigma.get(axis), true.get(axis),
                         seen.get(axis), step_deg)
        if err is not None and err.size:
            errs.append(err)
    for ax in grid[len(shown) - ncols:len(shown)]:  # the lowest panel of each column
        ax.set_xlabel("nominal readout (deg)")

    median = float(np.median(np.concatenate(errs))) if errs else None
    handles: list[Artist] = [Line2D([], [], ls="none", marker="o", ms=2.5, color="#0072b2",
                      label="identified" + ("" if median is None else
                                            f" (error bar: k = 1 uncertainty, median "
                                            f"{median:.2g} arcsec)"))]
    if any((~flags.get(a, np.ones(n, dtype=bool)) & seen.get(a, np.ones(n, dtype=bool))).any()
           for a in shown):
        handles.append(Line2D([], [], ls="none", marker="o", ms=4.5, mfc="none", mec="0.55",
                              label="not identifiable"))
    if any(a in true for a in shown):
        handles.append(Line2D([], [], color="black", lw=0.8, label="truth (in the fit's gauge)"))
    if any(not seen.get(a, np.ones(n, dtype=bool)).all() for a in shown):
        handles.append(Patch(color="0.88", label="no posture reached (not identified)"))
    if len(handles) > 1 or sigma:  # blue dots alone need no legend
        fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), frameon=False,
                   fontsize="small")
    fig.suptitle("Identified angular position measurement error of the encoders")
    fig.supylabel("angular position error (arcsec)", fontsize="medium")
    return fig


# --- Fig. 9: length errors on the bar ------------------------------------------------------------


def _length_table(results: Mapping[str, ValidationResult]
                  ) -> tuple[list[int], list[tuple[str, str]], dict[str, np.ndarray]]:
    """Return placements, socket pairs and model -> errors (placements x pairs, µm, NaN if absent)."""
    if not results:
        raise ValueError("results: no model given")
    pairs = list(dict.fromkeys(pair for r in results.values() for pair in r.pairs))
    if not pairs:
        raise ValueError("results: no socket pair has a length error")
    placements = sorted({int(k) for r in results.values() for k in r.placements})
    if not placements:
        raise ValueError("results: no bar placement has a length error")
    errors = {}
    for label, r in results.items():
        table = np.full((len(placements), len(pairs)), np.nan)
        for i, k in enumerate(r.placements):
            for j, pair in enumerate(r.pairs):
                table[placements.index(int(k)), pairs.index(pair)] = r.errors[i, j] * 1e6
        errors[label] = table
    return placements, pairs, errors


def _pair_title(pair: tuple[str, str]) -> str:
    """Return 'A-B' for the socket pair ('A', 'B')."""
    return f"{pair[0]}-{pair[1]}"


def plot_length_errors(results: Mapping[str, ValidationResult], path: str | Path) -> Path:
    """Plot the length errors per bar placement as grouped bars, one panel per socket pair (Fig. 9).

    Args:
        results: model label (e.g. "proposed, R-Test") -> its :func:`aacmm_pin.validate` result.
            Placements and pairs are the union over the models; an error a model did not measure
            (NaN) leaves its bar out.
        path: PNG file to write.

    Returns:
        ``path`` as a Path.

    Raises:
        ValueError: if ``results`` is empty or has no placement or no socket pair.
    """
    placements, pairs, errors = _length_table(results)
    n_models = len(errors)
    ncols = min(len(pairs), 2)
    nrows = math.ceil(len(pairs) / ncols)
    fig = new_figure(ncols * max(4.5, 0.2 * len(placements) * (n_models + 1)), 1.5 + 2.9 * nrows)
    grid = np.atleast_1d(fig.subplots(nrows, ncols, sharey=True, squeeze=False)).ravel()
    for ax in grid[len(pairs):]:
        ax.remove()
    finite = {label: err[np.isfinite(err)] for label, err in errors.items()}
    rms = {label: float(np.sqrt(np.mean(e ** 2))) if e.size else math.nan
           for label, e in finite.items()}
    x = np.arange(len(placements), dtype=float)
    width = 0.8 / n_models
    for j, (ax, pair) in enumerate(zip(grid, pairs)):
        for m, (label, err) in enumerate(errors.items()):
            ax.bar(x + (m - (n_models - 1) / 2) * width, err[:, j], width,
                   color=MODEL_COLOURS[m % len(MODEL_COLOURS)], edgecolor="black", linewidth=0.4,
                   label=f"{label} (RMS {rms[label]:.1f} µm)" if j == 0 else None, zorder=3)
        ax.axhline(0.0, color="black", lw=0.8, zorder=4)
        ax.set_xticks(x, [str(k) for k in placements])
        ax.set_xlabel("bar placement")
        ax.set_title(_pair_title(pair), loc="left", fontsize="medium", fontweight="bold")
        ax.grid(True, axis="y", lw=0.4, alpha=0.5, zorder=0)
        ax.tick_params(labelleft=True)
    for ax in grid[::ncols]:
        ax.set_ylabel("length error (µm)")
    fig.legend(loc="outside lower center", ncols=min(n_models, 3), frameon=False, fontsize="small")
    fig.suptitle("Length errors on the bar: measured minus calibrated socket distance")
    return _save(fig, path)
