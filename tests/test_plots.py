"""Tests of aacmm_pin.outputs.plots: the PNG figures of the R-Test profile, encoder maps and length errors."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin.outputs.plots
from aacmm_pin.analyses.validation import ValidationResult
from aacmm_pin.data.campaign import Campaign, SpatLog, read_campaign
from aacmm_pin.outputs.plots import (
    _encoder_map_figure,
    _rtest_displacement_figure,
    plot_encoder_maps,
    plot_length_errors,
    plot_rtest_displacement,
)
from tests.helpers import SAMPLE

N_NODES = 72  # 5 deg step


def _spat_campaign() -> Campaign:
    """Two R-Test locations; location 2 wanders farther (largest |XY| 20 um at its sample 31)."""
    rng = np.random.default_rng(0)
    n = 40
    d = rng.normal(0.0, 2e-6, (2 * n, 3))
    d[n + 30, :2] = [12e-6, -16e-6]
    return Campaign(spat=SpatLog(location=np.repeat([1, 2], n), q=rng.normal(size=(2 * n, 7)),
                                 displacement=d),
                    locations={1: np.zeros(3), 2: np.ones(3)}, lengthbar=None, bar={})


def _maps(axes: list[int]) -> dict[int, np.ndarray]:
    """Smooth maps of about 10 arcsec amplitude, in rad."""
    x = np.linspace(-np.pi, np.pi, N_NODES, endpoint=False)
    return {a: 5e-5 * np.sin(a * x + 0.3) for a in axes}


def _results() -> dict[str, ValidationResult]:
    """Validation results of three models, two socket pairs, four placements."""
    rng = np.random.default_rng(1)
    out = {}
    for label, scale in (("DH only, R-Test", 6.0), ("proposed, no R-Test", 3.0),
                         ("proposed, R-Test", 1.5)):
        out[label] = ValidationResult([1, 2, 3, 4], [("A", "B"), ("A", "C")],
                                      rng.normal(0.0, scale * 1e-6, (4, 2)))
    return out


def _assert_png(path: Path) -> None:
    """Check that ``path`` is a decodable PNG of a sensible size, not blank."""
    from matplotlib.image import imread

    assert path.is_file() and path.suffix == ".png"
    img = imread(path)
    h, w = img.shape[:2]
    assert 400 <= w <= 3000 and 300 <= h <= 3000, (w, h)
    ink = np.any(img[..., :3] < 0.95, axis=-1).mean()  # non-white pixels
    assert ink > 0.03, ink


def test_rtest_figure_is_a_png(tmp_path):
    """The R-Test figure is written as a non-blank PNG and the path is returned."""
    out = plot_rtest_displacement(_spat_campaign(), tmp_path / "fig5.png", location=1)
    assert out == tmp_path / "fig5.png"
    _assert_png(out)


def test_rtest_figure_of_the_sample_campaign(tmp_path):
    """The shared sample campaign (4 locations x 200 samples) plots with the default location."""
    if not SAMPLE.is_dir():
        pytest.skip("shared sample campaign not present")
    _assert_png(plot_rtest_displacement(read_campaign(SAMPLE), str(tmp_path / "sub" / "f.png")))


def test_rtest_default_location_is_the_largest_displacement():
    """location=None draws the location with the largest XY displacement, and annotates it in um."""
    fig = _rtest_displacement_figure(_spat_campaign())
    assert fig.get_suptitle().endswith("location #2")
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts == ["max |XY| 20.0 µm\n(sample 31)"]


def test_rtest_panels_show_um_and_samples():
    """The XY panel is dx/dy in um with equal aspect; the other panel is dz vs sample; a colorbar."""
    fig = _rtest_displacement_figure(_spat_campaign(), location=1)
    ax_xy, ax_z, bar = fig.axes
    assert (ax_xy.get_xlabel(), ax_xy.get_ylabel()) == ("dx (µm)", "dy (µm)")
    assert ax_xy.get_aspect() == 1.0
    assert (ax_z.get_xlabel(), ax_z.get_ylabel()) == ("sample", "dz (µm)")
    assert bar.get_ylabel() == "sample"


def test_rtest_unknown_location_names_the_argument(tmp_path):
    """An unknown location raises ValueError naming `location` and listing the valid ones."""
    with pytest.raises(ValueError, match=r"location: choose one of \[1, 2\]"):
        plot_rtest_displacement(_spat_campaign(), tmp_path / "x.png", location=7)
    assert not (tmp_path / "x.png").exists()


def test_rtest_without_spat_names_the_argument(tmp_path):
    """A campaign without SPAT raises ValueError naming `campaign`."""
    from aacmm_pin.data.campaign import LengthBarLog

    log = LengthBarLog(placement=[1, 1], socket=["A", "B"], q=np.zeros((2, 7)))
    campaign = Campaign(spat=None, locations={}, lengthbar=log, bar={("A", "B"): 0.3})
    with pytest.raises(ValueError, match="campaign"):
        plot_rtest_displacement(campaign, tmp_path / "x.png")


def test_encoder_map_figure_is_a_png(tmp_path):
    """The map figure with std, identifiability and truth is written as a non-blank PNG."""
    maps = _maps([1, 2, 3])
    flags = {a: np.ones(N_NODES, dtype=bool) for a in maps}
    flags[2][10:14] = False
    std = {a: np.full(N_NODES, 3e-6) for a in maps}
    out = plot_encoder_maps(maps, tmp_path / "fig6.png", identifiable=flags, std=std, truth=maps)
    _assert_png(out)


@pytest.mark.parametrize("axes", [[1], [2, 5], [1, 2, 3], [1, 2, 3, 4, 5, 6, 7]])
def test_encoder_map_figure_has_one_panel_per_axis(axes):
    """The map figure has exactly one panel per requested axis, titled A{n}-axis, in order."""
    fig = _encoder_map_figure(_maps(list(range(1, 8))), axes=axes)
    assert [ax.get_title(loc="left") for ax in fig.axes] == [f"A{a}-axis" for a in axes]


def test_encoder_map_default_axes_are_the_sorted_keys():
    """Without `axes`, the panels are the keys of `maps`, sorted."""
    fig = _encoder_map_figure(_maps([3, 1, 2]))
    assert [ax.get_title(loc="left") for ax in fig.axes] == ["A1-axis", "A2-axis", "A3-axis"]


def test_encoder_map_note_counts_unidentifiable_nodes():
    """A panel with non-identifiable nodes says 'n of N nodes not identifiable'; others say nothing."""
    flags = {1: np.ones(N_NODES, dtype=bool), 2: np.ones(N_NODES, dtype=bool)}
    flags[2][[0, 5, 40]] = False
    fig = _encoder_map_figure(_maps([1, 2]), identifiable=flags)
    notes = [ax.get_title(loc="right") for ax in fig.axes]
    assert notes == ["", f"3 of {N_NODES} nodes not identifiable"]


def test_encoder_map_data_in_display_units():
    """Node angles are drawn in deg from -180 and errors in arcsec (rad * 180/pi * 3600)."""
    maps = {1: np.full(N_NODES, 1e-5)}
    fig = _encoder_map_figure(maps)
    (dots,) = [ln for ln in fig.axes[0].lines if ln.get_marker() == "o" and len(ln.get_xdata())]
    assert np.allclose(dots.get_xdata(), np.arange(-180.0, 180.0, 5.0))
    assert np.allclose(dots.get_ydata(), 1e-5 * 180 / np.pi * 3600)
    assert "(arcsec)" in fig.get_supylabel()


def test_encoder_map_axis_the_data_cannot_see_is_flat_not_magnified():
    """An A7 map of numerical noise (1e-12 arcsec) with a 'truth' of rounding noise: the panel
    spans at least +-1 arcsec, so it reads as zero, and the truth line is exactly 0."""
    tiny = {7: np.random.default_rng(0).normal(0.0, 1e-17, N_NODES)}
    fig = _encoder_map_figure(tiny, truth=tiny)
    low, high = fig.axes[0].get_ylim()
    assert low <= -1.0 and high >= 1.0
    truth_line = [ln for ln in fig.axes[0].lines if ln.get_marker() in ("None", "", None)
                  and len(ln.get_xdata()) == N_NODES + 1]
    assert truth_line and np.all(truth_line[0].get_ydata() == 0.0)
    big = _encoder_map_figure({1: np.full(N_NODES, 20 * np.pi / 180 / 3600)})
    assert big.axes[0].get_ylim()[1] > 20.0  # a real error keeps its own scale


def test_encoder_map_error_bars_are_stated():
    """Error bars smaller than a marker are still stated: the legend gives the median k=1 std."""
    maps = _maps([1, 2])
    std = {a: np.full(N_NODES, 0.3 * np.pi / 180 / 3600) for a in maps}
    fig = _encoder_map_figure(maps, std=std)
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert any("median 0.3 arcsec" in t for t in labels), labels


def test_rtest_postures_are_points_not_a_path_and_the_zero_is_on_top():
    """Fig. 5: samples are separate postures (no line joins them); the zero marker is drawn above."""
    from matplotlib.collections import LineCollection

    fig = _rtest_displacement_figure(_spat_campaign(), location=1)
    ax_xy, ax_z = fig.axes[:2]
    assert not [c for c in ax_xy.collections if isinstance(c, LineCollection)]
    assert not [ln for ln in ax_z.lines if len(ln.get_xdata()) > 2]  # only the zero line
    zero = [ln for ln in ax_xy.lines if ln.get_marker() == "+"]
    assert zero and min(ln.get_zorder() for ln in zero) > max(c.get_zorder() for c in ax_xy.collections)


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"maps": {1: np.zeros(N_NODES - 1)}}, "maps"),
    ({"maps": {1: np.zeros(N_NODES)}, "step_deg": 10.0}, "maps"),
    ({"maps": {1: np.zeros(N_NODES)}, "std": {1: np.zeros(3)}}, "std"),
    ({"maps": {1: np.zeros(N_NODES)}, "truth": {1: np.zeros(3)}}, "truth"),
    ({"maps": {1: np.zeros(N_NODES)}, "identifiable": {1: np.ones(3, dtype=bool)}}, "identifiable"),
    ({"maps": {1: np.zeros(N_NODES)}, "step_deg": 7.0}, "step_deg"),
    ({"maps": {1: np.zeros(N_NODES)}, "axes": [2]}, "axes"),
    ({"maps": {1: np.zeros(N_NODES)}, "axes": []}, "axes"),
    ({"maps": {}}, "maps"),
])
def test_encoder_map_bad_input_names_the_argument(tmp_path, kwargs, name):
    """Wrong map lengths for the step, bad steps and unknown axes raise ValueError naming the argument."""
    with pytest.raises(ValueError, match=rf"^{name}:"):
        plot_encoder_maps(path=tmp_path / "x.png", **kwargs)
    assert not (tmp_path / "x.png").exists()


def test_length_error_figure_is_a_png(tmp_path):
    """The length-error figure of three models and two pairs is written as a non-blank PNG."""
    _assert_png(plot_length_errors(_results(), tmp_path / "fig9.png"))


def test_length_error_figure_tolerates_missing_values(tmp_path):
    """An unmeasured error (NaN) and a placement one model lacks still give a figure."""
    results = _results()
    model = results["proposed, R-Test"]
    errors = np.delete(model.errors.copy(), 2, axis=0)
    errors[0, 1] = np.nan
    results["proposed, R-Test"] = ValidationResult([1, 2, 4], model.pairs, errors)
    _assert_png(plot_length_errors(results, tmp_path / "fig9.png"))


def test_length_error_table_aligns_placements_and_pairs():
    """Models with other placements and pair orders land in the right cells, in um."""
    from aacmm_pin.outputs.plots import _length_table

    a = ValidationResult([1, 2], [("A", "B"), ("A", "C")], np.array([[1.0, 2.0], [3.0, 4.0]]) * 1e-6)
    b = ValidationResult([2, 3], [("A", "C")], np.array([[5.0], [6.0]]) * 1e-6)
    placements, pairs, errors = _length_table({"a": a, "b": b})
    assert placements == [1, 2, 3] and pairs == [("A", "B"), ("A", "C")]
    np.testing.assert_allclose(errors["a"], [[1, 2], [3, 4], [np.nan, np.nan]])
    np.testing.assert_allclose(errors["b"], [[np.nan, np.nan], [np.nan, 5], [np.nan, 6]])


@pytest.mark.parametrize("results", [
    {},
    {"proposed": ValidationResult([1], [], np.zeros((1, 0)))},
    {"proposed": ValidationResult([], [("A", "B")], np.zeros((0, 1)))},
])
def test_length_error_bad_results_name_the_argument(tmp_path, results):
    """Empty results, no socket pair and no placement raise ValueError naming the argument."""
    with pytest.raises(ValueError, match=r"^results:"):
        plot_length_errors(results, tmp_path / "x.png")


def test_plots_module_does_not_import_matplotlib():
    """aacmm_pin.outputs.plots imports matplotlib only inside functions (or under TYPE_CHECKING)."""
    tree = ast.parse(Path(aacmm_pin.outputs.plots.__file__).read_text(encoding="utf-8"))
    top = [node for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))]
    names = [a.name for n in top if isinstance(n, ast.Import) for a in n.names]
    names += [n.module or "" for n in top if isinstance(n, ast.ImportFrom)]
    assert names and not [n for n in names if n.split(".")[0] == "matplotlib"]


def test_discovery_step_figure_draws_every_named_term():
    """A step that names compliance on six axes draws six panels (not the first four)."""
    from types import SimpleNamespace

    from aacmm_pin.outputs.discovery_figures import _step_figure

    rng = np.random.default_rng(0)
    views = [{"term": f"compliance[A{a}]", "variable": f"gravity torque on A{a} (N m)",
              "x": rng.normal(size=50), "residual": "residual along the term (um)",
              "before": rng.normal(size=50), "after": rng.normal(size=50)} for a in range(1, 7)]
    step = SimpleNamespace(views=views, effect="compliance", axes=list(range(1, 7)),
                           heldout_rms_before=3e-6, heldout_rms_after=2e-6)
    fig = _step_figure(step, 1)
    assert sorted(ax.get_title() for ax in fig.axes) == [f"compliance[A{a}]" for a in range(1, 7)]


def _panel_lines(fig, panel: int) -> tuple[np.ndarray, list]:
    """The truth line's y at the nodes (closing point dropped) and the marker lines of a panel."""
    ax = fig.axes[panel]
    (truth,) = [ln for ln in ax.lines if ln.get_marker() in ("None", "", None)
                and len(ln.get_xdata()) == N_NODES + 1]
    marks = [ln for ln in ax.lines if ln.get_marker() == "o" and len(ln.get_xdata())]
    return np.asarray(truth.get_ydata())[:-1], marks


def test_encoder_map_truth_is_honest_where_no_posture_reached(small_sim, small_cal):
    """Issue 26 item 6. Fig. 6 of a fit whose postures leave part of a map unreached: there the
    truth line is the truth itself (moved only by the map's gauge constant), not the fit's
    held zero; no identified value is drawn there; the range is shaded; the line is labelled."""
    from aacmm_pin.units import ARCSEC

    cal, truth = small_cal, small_sim.truth
    reached = cal.node_reached
    axes = sorted(cal.node_identifiable)
    fig = _encoder_map_figure({a: cal.parameters.map(a).values for a in axes},
                              identifiable=cal.node_identifiable,
                              truth=cal.maps_in_gauge(truth), reached=reached)
    x_deg = np.arange(-180.0, 180.0, 5.0)
    checked = 0
    for panel, a in enumerate(axes):
        line, marks = _panel_lines(fig, panel)
        away = ~reached[a]
        for ln in marks:  # no identified (or "not identifiable") value where nothing reached
            assert not np.isin(np.asarray(ln.get_xdata()), x_deg[away]).any(), a
        if not away.any():
            continue
        own = truth.map(a).values[away] / ARCSEC
        if np.ptp(own) < 1.0:  # a truth too flat there to tell a held zero from it
            continue
        gap = line[away] - own  # one constant: the gauge
        assert np.ptp(gap) < 1e-6 * np.ptp(own), a
        assert np.max(np.abs(line[away])) > 1.0, a  # arcsec: not the held zero
        shaded = [p for p in fig.axes[panel].patches]
        centres = [x for x in x_deg[away]
                   if not any(p.get_x() <= x <= p.get_x() + p.get_width() for p in shaded)]
        assert not centres, (a, centres)
        checked += 1
    assert checked >= 2  # the small campaign leaves parts of several maps unreached
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert "truth (in the fit's gauge)" in labels and any("no posture" in t for t in labels)


def test_encoder_map_truth_in_gauge_is_the_equivalent_where_reached(small_sim, small_cal):
    """On reached nodes the truth in the fit's gauge is what the fit can return at best (the
    equivalent), unchanged: the figure's comparison there is the one it always was."""
    moved, _ = small_cal.equivalent(small_sim.truth)
    shown = small_cal.maps_in_gauge(small_sim.truth)
    for a, hit in small_cal.node_reached.items():
        assert hit.any() and np.array_equal(shown[a][hit], moved.map(a).values[hit])
