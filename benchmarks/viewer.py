"""Load time of the MeshCat viewer on a 10k-sample campaign (static HTML and live server).

Run: ``python benchmarks/viewer.py`` (prints a markdown section for BENCHMARKS.md; needs Debian's
``chromium`` and PyPI ``playwright``, used with ``executable_path``: nothing is downloaded).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import SimulationConfig, identify, load_arm, simulate_campaign  # noqa: E402
from aacmm_pin.outputs.viewer import View, serve, view  # noqa: E402
from benchmarks._report import machine, write_section  # noqa: E402

SAMPLES_PER_LOCATION = 2500  # x 4 locations = 10,000 SPAT samples
FLAGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--no-first-run"]
JS_MISSING = """paths => paths.filter(p => {
  let n = viewer.scene_tree;
  for (const k of p.split('/').filter(Boolean)) { n = n.children[k]; if (!n) return true; }
  return !n.children['<object>'];
})"""
JS_FRAME_MS = """n => {  // draw n frames while orbiting; readPixels waits for each to finish
  viewer.animator.pause();
  const gl = viewer.renderer.getContext(), px = new Uint8Array(4), t0 = performance.now();
  const cam = viewer.camera.position, c = Math.cos(0.02), s = Math.sin(0.02);
  for (let i = 0; i < n; i++) {  // about the vertical (the camera's parent frame is y-up)
    [cam.x, cam.z] = [c * cam.x - s * cam.z, s * cam.x + c * cam.z];
    viewer.camera.lookAt(0, 0, 0);
    viewer.render();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  }
  return (performance.now() - t0) / n;
}"""
JS_FPS = """() => new Promise(done => {  // frames the page shows per second while orbiting (rAF)
  const cam = viewer.camera.position, c = Math.cos(0.02), s = Math.sin(0.02), t0 = performance.now();
  let frames = 0;
  function step() {
    [cam.x, cam.z] = [c * cam.x - s * cam.z, s * cam.x + c * cam.z];
    viewer.camera.lookAt(0, 0, 0);
    viewer.set_dirty();
    frames++;
    if (performance.now() - t0 < 2000) requestAnimationFrame(step);
    else done(frames * 1000 / (performance.now() - t0));
  }
  requestAnimationFrame(step);
})"""


def best(f, repeat: int = 3) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        tic = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - tic)
    return min(times), out


def load_static(context, html: Path) -> float:
    page = context.new_page()
    tic = time.perf_counter()
    page.goto(html.as_uri())
    page.wait_for_function("() => window.aacmm_pin && window.aacmm_pin.ready", timeout=120_000)
    page.evaluate(JS_FRAME_MS, 1)
    elapsed = time.perf_counter() - tic
    page.close()
    return elapsed


def load_live(context, url: str, paths: list[str]) -> float:
    page = context.new_page()
    tic = time.perf_counter()
    page.goto(url)
    page.wait_for_function(f"() => viewer.connection.readyState === 1 && ({JS_MISSING})({paths!r})"
                           ".length === 0", timeout=120_000)
    page.evaluate(JS_FRAME_MS, 1)
    elapsed = time.perf_counter() - tic
    page.close()
    return elapsed


def drawing(context, html: Path) -> dict[str, tuple[float, float]]:
    """Frame time (ms) and frames per second while orbiting, with and without the residuals."""
    page = context.new_page()
    page.goto(html.as_uri())
    page.wait_for_function("() => window.aacmm_pin && window.aacmm_pin.ready", timeout=120_000)
    out = {}
    for case, visible in (("shown", True), ("hidden", False)):
        page.evaluate("v => viewer.set_property(['meshcat', 'models'], 'visible', v)", visible)
        page.evaluate(JS_FRAME_MS, 5)  # warm up
        out[case] = (min(page.evaluate(JS_FRAME_MS, 10) for _ in range(3)), page.evaluate(JS_FPS))
    page.close()
    return out


def main() -> None:
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium")
    if chromium is None:
        sys.exit("benchmarks/viewer.py: no chromium on PATH (apt-get install chromium)")
    tic = time.perf_counter()
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(samples_per_location=SAMPLES_PER_LOCATION))
    n = len(sim.campaign.spat.location)
    cals = {m: identify(sim.campaign, arm, model=m).parameters for m in ("dh", "proposed")}
    print(f"simulated and identified in {time.perf_counter() - tic:.1f} s", file=sys.stderr)
    tmp = Path(tempfile.mkdtemp())
    html = tmp / "view.html"
    view(cals["dh"], sim.campaign, html=html)  # imports (meshcat, matplotlib) out of the timing
    t_build, result = best(lambda: view(cals["dh"], sim.campaign, html=html, compare=[cals["proposed"]]))
    scene = result.scene
    n_objects = sum(kind == "set_object" for kind, _, _ in scene.commands)
    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(tmp / "profile"), executable_path=chromium, headless=True, args=FLAGS,
            viewport={"width": 1280, "height": 800})
        t_static = min(load_static(context, html) for _ in range(3))
        draw = drawing(context, html)
        tic = time.perf_counter()
        live = View(scene, visualizer=serve(scene))  # prints its URL
        t_serve = time.perf_counter() - tic
        try:
            paths = scene.info["arm_paths"] + scene.info["residual_paths"]
            t_live = min(load_live(context, str(live.url), paths) for _ in range(3))
        finally:
            live.close()
        context.close()
    (ms_on, fps_on), (ms_off, fps_off) = draw["shown"], draw["hidden"]
    write_section("viewer", f"""## Viewer on a 10k-sample campaign (`python benchmarks/viewer.py`)

{machine()}.
Headless Debian Chromium at 1280 x 800, WebGL in software (SwiftShader, on the CPU).
{n:,} SPAT samples (4 locations x {SAMPLES_PER_LOCATION}) and {len(sim.campaign.lengthbar.q):,} bar \
readouts; two models (DH shown, proposed hidden),
each drawn as 5 batched objects (predicted points, measured points, arrow shafts, arrow heads,
bars): {n_objects} `set_object` commands in all, whatever the number of samples. Best of 3 (wall time: the
browser's drawing; the best run is the least disturbed by other jobs). Load times with no baseline:
there is no other viewer of these scenes to compare with.

| step | time |
|---|---|
| build the scene and write the HTML (`view(..., html=FILE)`) | {t_build:.2f} s |
| static HTML size | {html.stat().st_size / 1e6:.1f} MB |
| open the static HTML until the scene is complete and drawn once | {t_static:.2f} s |
| send the scene to a live MeshCat server (`serve`) | {t_serve:.2f} s |
| open the live page until every object has arrived and is drawn once | {t_live:.2f} s |
| one frame while orbiting, 10k residuals shown / models hidden | {ms_on:.0f} / {ms_off:.0f} ms |
| frames per second while orbiting, 10k residuals shown / models hidden | {fps_on:.1f} / {fps_off:.1f} |""")


if __name__ == "__main__":
    main()
