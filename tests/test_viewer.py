"""The MeshCat viewer: its recorded scene, the static HTML and the live server, in headless Chromium.

The browser tests drive Debian's ``chromium`` (``.ci/run`` installs it with apt-get) through PyPI
``playwright`` with ``executable_path``: nothing is downloaded. They skip only where chromium is
absent. ``AACMM_PIN_VIEWER_PNG=examples/figures/viewer.png python -m pytest tests/test_viewer.py``
also writes the README screenshot.
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import os
import re
import shutil
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from aacmm_pin.cli.viewer import add_parsers
from aacmm_pin.data.campaign import Campaign, read_campaign, write_campaign
from aacmm_pin.effects.calibrated import predict
from aacmm_pin.fit.identification import identify
from aacmm_pin.model.arm import load_arm
from aacmm_pin.model.parameters import read_parameters
from aacmm_pin.outputs.export import write_calibration
from aacmm_pin.outputs.viewer import view

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--no-first-run"]  # --user-data-dir: the fresh profile folder of launch_persistent_context
VIEWPORT = {"width": 1000, "height": 650}
SCREENSHOT_ENV = "AACMM_PIN_VIEWER_PNG"

# Scene-tree lookups that never create nodes (viewer.scene_tree.find() would), and a capture of the
# 3-D content alone: background, grid, axes and the legend panels hidden.
JS_MISSING = """paths => paths.filter(p => {
  let n = viewer.scene_tree;
  for (const k of p.split('/').filter(Boolean)) { n = n.children[k]; if (!n) return true; }
  return !n.children['<object>'];
})"""
JS_NODE = """path => {
  let n = viewer.scene_tree;
  for (const k of path.split('/').filter(Boolean)) { n = n.children[k]; if (!n) return null; }
  return n.object;
}"""
JS_IN_MESHCAT = f"""path => {{
  const node = {JS_NODE}, o = node(path), root = node('/meshcat');
  root.updateMatrixWorld(true);
  return [Array.from(o.matrixWorld.elements), Array.from(root.matrixWorld.elements)];
}}"""
JS_CAPTURE = """hide => {
  const paths = hide.map(p => p.split('/').filter(Boolean));
  const was = paths.map(p => viewer.scene_tree.find(p).object.visible);
  for (const p of paths) viewer.set_property(p, 'visible', false);
  const url = viewer.capture_image();
  paths.forEach((p, i) => viewer.set_property(p, 'visible', was[i]));
  return url;
}"""
CHROME = ["/Background", "/Grid", "/Axes", "/Cameras/default/rotated/<object>/legend",
          "/Cameras/default/rotated/<object>/coverage"]


@pytest.fixture(scope="module")
def folders(tmp_path_factory, arm, small_sim, small_cal):
    """The shared small simulated campaign and its DH and proposed calibration folders."""
    out = tmp_path_factory.mktemp("viewer")
    write_campaign(small_sim.campaign, out / "campaign")
    write_calibration(identify(small_sim.campaign, arm, model="dh"), arm, out / "dh")
    write_calibration(small_cal, arm, out / "proposed")
    return out


@pytest.fixture(scope="module")
def static(folders):
    """The static HTML of the DH calibration compared with the proposed one."""
    result = view(folders / "dh", folders / "campaign", html=folders / "view.html",
                  compare=[folders / "proposed"])
    return result


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """Headless Debian chromium under playwright (one fresh profile for the module)."""
    if CHROMIUM is None:
        pytest.skip("no chromium on PATH (Debian package 'chromium', installed by .ci/run): "
                    "MeshCat's WebGL page cannot be rendered")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp_path_factory.mktemp("chromium-profile")), executable_path=CHROMIUM,
            headless=True, args=FLAGS, viewport=VIEWPORT)
        yield context
        context.close()


def _independent_residuals(folders: Path, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nest, predicted and measured centres in the r-CS, from the files (Eq. 3-4 by hand)."""
    campaign = read_campaign(folders / "campaign")
    params = read_parameters(folders / label)
    rot, t = params.rotation(), params.translation
    spat = campaign.spat
    nest_mt = np.array([campaign.locations[int(m)] for m in spat.location])
    offsets = json.loads((folders / label / "report.json").read_text())["nest_offsets_um"]
    offset = np.array([offsets.get(str(int(m)), [0.0] * 3) for m in spat.location]) * 1e-6
    to_r = np.linalg.inv(rot)
    nest = (nest_mt - t) @ to_r.T
    measured = (nest_mt + offset + spat.displacement - t) @ to_r.T
    return nest, predict(load_arm(params.arm), params, spat.q), measured


def _buffer(scene, path: str, attribute: str = "position") -> np.ndarray:
    """Decode one attribute of the geometry last set at ``path`` in the recorded commands."""
    import umsgpack

    data = [d for kind, p, d in scene.commands if kind == "set_object" and p == path][-1]
    attr = umsgpack.unpackb(data)["object"]["geometries"][0]["data"]["attributes"][attribute]
    return np.frombuffer(attr["array"].data, dtype=np.float32).reshape(-1, attr["itemSize"])


def test_import_leaves_meshcat_and_matplotlib_out():
    """Importing the viewer imports neither meshcat nor matplotlib (they load inside functions)."""
    code = ("import sys, aacmm_pin.outputs.viewer, aacmm_pin.outputs._viewer_scene; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'meshcat', 'matplotlib'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == "[]"


def test_scene_draws_every_residual_magnified_in_few_objects(folders, static):
    """Each model's N arrows go from the predicted to the measured centre, magnified about the nest."""
    scene = static.scene
    assert static.labels == ["dh", "proposed"] and static.url is None
    for label in ("dh", "proposed"):
        nest, pred, meas = _independent_residuals(folders, label)
        seg = _buffer(scene, f"/meshcat/models/{label}/residuals")
        assert seg.shape == (2 * len(nest), 3)
        k = scene.scale
        np.testing.assert_allclose(seg[0::2], nest + k * (pred - nest), atol=2e-6)  # float32 buffers
        np.testing.assert_allclose(seg[1::2], nest + k * (meas - nest), atol=2e-6)  # float32 buffers
        info = next(m for m in scene.info["models"] if m["label"] == label)
        assert info["rms_um"] == pytest.approx(np.sqrt(np.mean((pred - meas) ** 2)) * 1e6, rel=1e-6)
    rms = {m["label"]: m["rms_um"] for m in scene.info["models"]}
    assert rms["proposed"] < rms["dh"] / 3  # the encoder maps shrink the residuals
    for label in ("dh", "proposed"):  # the same number identify reported for the calibration
        report = json.loads((folders / label / "report.json").read_text())
        # files round readouts to 1e-9 deg (~2e-11 m at 1 m reach) and mm to 9 decimals
        assert rms[label] == pytest.approx(report["fit_rms_um"], rel=1e-5)
    objects = [p for kind, p, _ in scene.commands if kind == "set_object"]
    assert len(objects) < 60  # batched: not one object per sample
    # the first model's RMS residual drawn 10-20 mm long (1-2-5 steps): its arrows show
    assert 0.01 <= scene.scale * rms["dh"] * 1e-6 <= 0.02 and scene.info["scale"] == scene.scale
    assert scene.info["vmax_um"] >= max(
        m["max_um"] for m in scene.info["models"]) * 0.5
    q = read_campaign(folders / "campaign").spat.q
    for axis, counts in scene.coverage.items():
        wrapped = (np.degrees(q[:, axis - 1]) + 180) % 360 - 180  # periodic: 180 deg is -180 deg
        hist, _ = np.histogram(wrapped, bins=np.arange(-180, 181, 5.0))
        np.testing.assert_array_equal(counts, hist)


def test_spat_only_and_bar_only_campaigns_are_drawn(folders, tmp_path):
    """A campaign without length bar has no bars; one without SPATs has no residual arrows."""
    full = read_campaign(folders / "campaign")
    spat_only = Campaign(spat=full.spat, locations=full.locations, lengthbar=None, bar={})
    bar_only = Campaign(spat=None, locations={}, lengthbar=full.lengthbar, bar=full.bar)
    paths = view(folders / "dh", spat_only, html=tmp_path / "a.html").scene.info["residual_paths"]
    assert "/meshcat/models/dh/residuals" in paths and "/meshcat/models/dh/bar" not in paths
    scene = view(folders / "dh", bar_only, html=tmp_path / "b.html").scene
    assert scene.info["residual_paths"] == ["/meshcat/models/dh/bar"] and scene.location is None
    with pytest.raises(ValueError, match="location"):
        view(folders / "dh", full, html=tmp_path / "c.html", location=9)


def test_cli_view_writes_one_self_contained_file(folders, tmp_path, capsys):
    """``aacmm-pin view CALDIR CAMPAIGN --html FILE --compare CALDIR2`` writes one offline page."""
    parser = argparse.ArgumentParser(prog="aacmm-pin")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    out = tmp_path / "report" / "view.html"
    args = parser.parse_args(["view", str(folders / "proposed"), str(folders / "campaign"),
                              "--html", str(out), "--compare", str(folders / "dh"),
                              "--location", "2"])
    assert args.handler(args) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    text = out.read_text()
    tags = _Tags()
    tags.feed(text)
    assert tags.names >= {"html", "script", "div"} and tags.external == []  # nothing to fetch
    assert {u for u in re.findall(r"https?://[^\s\"'<>)]+", text)} <= {"http://www.w3.org/1999/xhtml"}
    assert '"location": 2' in text and 200_000 < len(text) < 5_000_000


def test_cli_view_serves_until_told_then_stops_the_server(folders, capsys):
    """Without --html, ``view`` serves on localhost, prints the URL and stops the server after."""
    from urllib.error import URLError
    from urllib.request import urlopen

    parser = argparse.ArgumentParser(prog="aacmm-pin")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["view", str(folders / "proposed"), str(folders / "campaign"),
                              "--serve-for", "0.2"])
    assert args.handler(args) == 0
    url = re.search(r"serving (http://127\.0\.0\.1:\d+/static/)", capsys.readouterr().out).group(1)
    with pytest.raises(URLError):
        urlopen(url, timeout=2)


def test_static_html_renders_offline_in_chromium(folders, static, browser):
    """The file renders offline: arm links and residuals in the scene tree, posed as Pinocchio says."""
    page = browser.new_page()
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.goto(static.html.resolve().as_uri())
    page.wait_for_function("() => window.aacmm_pin && window.aacmm_pin.ready", timeout=20_000)
    info = page.evaluate("() => window.aacmm_pin")
    assert len(info["arm_paths"]) == 11 and "/meshcat/arm/visuals/link2_0" in info["arm_paths"]
    assert "/meshcat/models/dh/residuals" in info["residual_paths"]
    assert page.evaluate(JS_MISSING, info["arm_paths"] + info["residual_paths"]) == []
    n_vertices = page.evaluate(f"() => ({JS_NODE})('/meshcat/models/proposed/residuals/<object>')"
                               ".geometry.attributes.position.count")
    assert n_vertices == 2 * 200
    page.evaluate("() => { viewer.animator.pause(); viewer.animator.seek(0); }")
    _assert_stylus_at(page, static, read_campaign(folders / "campaign").spat.q[info["postures"][0]])
    drawn = _drawn_pixels(page, CHROME)
    without_residuals = _drawn_pixels(page, CHROME + ["/meshcat/models"])
    assert drawn > 0.01 * VIEWPORT["width"] * VIEWPORT["height"]  # not blank
    assert drawn - without_residuals > 500  # the residuals themselves are drawn
    assert all(u.startswith(("file:", "data:")) for u in requests), requests
    if os.environ.get(SCREENSHOT_ENV):
        page.wait_for_timeout(500)  # textures of the legend panels
        page.screenshot(path=os.environ[SCREENSHOT_ENV])
    page.close()


def test_live_server_page_in_chromium_and_pose(folders, browser, capsys):
    """The live server prints a localhost URL, serves the scene; pose() and show_model() act on it."""
    result = view(folders / "proposed", folders / "campaign", compare=[folders / "dh"])
    try:
        assert result.url.startswith("http://127.0.0.1:") and result.url in capsys.readouterr().out
        page = browser.new_page()
        page.goto(result.url)
        paths = result.scene.info["arm_paths"] + result.scene.info["residual_paths"]
        page.wait_for_function(f"() => viewer.connection.readyState === 1 && ({JS_MISSING})"
                               f"({paths!r}).length === 0", timeout=20_000)
        assert _drawn_pixels(page, CHROME) > 0.01 * VIEWPORT["width"] * VIEWPORT["height"]
        page.evaluate("() => viewer.animator.pause()")
        q = np.radians([30, -20, 40, 60, -30, 45, 10])
        result.pose(q)
        _assert_stylus_at(page, result, q, wait_s=10.0)  # the pose goes over the websocket
        result.show_model("dh")
        page.wait_for_function(f"() => ({JS_NODE})('/meshcat/models/dh').visible && "
                               f"!({JS_NODE})('/meshcat/models/proposed').visible", timeout=5_000)
        page.close()
    finally:
        proc = result._vis.window.server_proc if result._vis is not None else None
        result.close()
    assert proc is None or proc.poll() is not None


class _Tags(HTMLParser):
    """Tag names of a page and every src/href that is not inline data (script bodies not parsed)."""

    def __init__(self) -> None:
        super().__init__()
        self.names: set[str] = set()
        self.external: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.names.add(tag)
        self.external += [v for k, v in attrs if k in ("src", "href") and v and not v.startswith("data:")]


def _assert_stylus_at(page, result, q: np.ndarray, wait_s: float = 0.0) -> None:
    """The drawn stylus sphere sits at Pinocchio's stylus centre for readouts ``q`` (r-CS).

    ``wait_s``: how long the page may take to get there (a pose sent to a live page arrives
    over its websocket); the position is read every 50 ms until it matches or the time is up.
    """
    model = result.scene.models[0]
    predicted = predict(model.arm, model.params, q[None])[0]
    deadline = time.monotonic() + wait_s
    while True:
        world, root = (np.array(m).reshape(4, 4).T for m in
                       page.evaluate(JS_IN_MESHCAT, "/meshcat/arm/visuals/stylus_0"))
        drawn = (np.linalg.inv(root) @ world)[:3, 3]
        if np.allclose(drawn, predicted, rtol=0.0, atol=1e-6) or time.monotonic() > deadline:
            break
        page.wait_for_timeout(50)
    np.testing.assert_allclose(drawn, predicted, atol=1e-6)


def _drawn_pixels(page, hide: list[str]) -> int:
    """Number of pixels the renderer drew with ``hide`` hidden (transparent background)."""
    from PIL import Image

    url = page.evaluate(JS_CAPTURE, hide)
    rgba = np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGBA"))
    return int((rgba[..., 3] > 0).sum())


def test_auto_scale_shows_a_good_model_and_a_poor_one():
    """The default magnification draws the first model's RMS residual 10-20 mm long (1-2-5
    steps): 1.9 um -> 10000x, 26 um -> 500x; clamped to 100..100000."""
    from aacmm_pin.outputs._viewer_scene import auto_scale

    def model(rms_um: float):
        return SimpleNamespace(rms=rms_um * 1e-6)

    assert auto_scale(model(1.9)) == 10000.0 and auto_scale(model(26.0)) == 500.0
    for rms_um in (0.7, 1.9, 3.3, 26.0, 140.0):
        assert 0.01 <= auto_scale(model(rms_um)) * rms_um * 1e-6 <= 0.02
    assert auto_scale(model(1e-6)) == 1e5 and auto_scale(model(1e6)) == 100.0


def test_each_model_spans_its_own_colour_scale(static):
    """Issue 26 item 9: a good model's arrows are not one colour because a poor model is shown
    beside it: each model's colour top is its own 99th-percentile |residual| (1-2-5 rounded up),
    so its arrows use at least half of the colour map, and the legend states each model's top."""
    from aacmm_pin.outputs._viewer_scene import _colormap

    scene = static.scene
    ramp = np.asarray(_colormap()(np.linspace(0.0, 1.0, 256)))[:, :3]
    for m, top in zip(scene.models, scene.colour_tops):
        err = np.linalg.norm(m.residual, axis=1)
        assert np.percentile(err, 99) <= top <= 5 * np.percentile(err, 99) / 2  # 1-2-5 rounding
        colours = _buffer(scene, f"/meshcat/models/{m.label}/residuals", "color")[0::2]
        where = np.argmin(((colours[:, None, :] - ramp[None]) ** 2).sum(-1), axis=1) / 255
        assert where.max() - where.min() >= 0.5, (m.label, where.min(), where.max())
        info = next(i for i in scene.info["models"] if i["label"] == m.label)
        assert info["colour_top_um"] == pytest.approx(top * 1e6)


def test_legend_lines_fit_inside_the_panel(static):
    """Issue 26 item 9: no legend text runs past the panel's right edge (it used to be clipped)."""
    from aacmm_pin.outputs._viewer_scene import _legend_figure

    fig = _legend_figure(static.scene)
    renderer = fig.canvas.get_renderer()
    width = fig.bbox.width
    texts = [t for t in fig.texts] + [fig.axes[0].title]
    assert len(texts) >= 5
    for t in texts:
        box = t.get_window_extent(renderer)
        assert 0 <= box.x0 and box.x1 <= width, (t.get_text(), box.x1, width)
    shown = "\n".join(t.get_text() for t in fig.texts)
    for top in static.scene.colour_tops:
        assert f"colours 0-{top * 1e6:g} µm" in shown.replace("\n   ", " ")
