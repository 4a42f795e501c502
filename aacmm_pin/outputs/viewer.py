r"""MeshCat viewer of a calibration on its campaign: the arm, the R-Test nests, the bar, the residuals.

:func:`view` draws, in the r-CS of the (first) calibration:

* the arm from its URDF (Pinocchio's MeshCat visualiser), posed at a SPAT posture; the animation
  (Controls > Animations) steps through the SPAT postures of one R-Test location, time ``t`` s
  showing posture ``t``; :meth:`View.pose` poses it from Python on a live server;
* the R-Test nests (with a ring of 10 µm, magnified) and the length-bar sockets;
* for every SPAT sample the predicted stylus centre with an arrow to the measured sphere centre,
  coloured by the magnitude of the residual on the model's own scale (0 to its 99th percentile,
  rounded up; each model's top in the legend panel), the deviations from each nest
  magnified ``scale`` times (by default so that the first model's RMS residual is ~20 mm long);
* the bar of every placement coloured by its largest length error;
* one group ``models/<label>`` per calibration, the first shown and the others hidden: tick them
  in Controls > Scene to see the residuals shrink from one model to the next;
* a coverage panel: which readout bins of every axis the SPATs and the bar visited.

Without ``html`` a MeshCat server is started on localhost, prints its URL and is stopped by
:meth:`View.close` (or the ``with`` block); with ``html`` the scene is written to one self-contained
file (viewer JavaScript and data inlined: it opens offline) and no server is started. meshcat is
imported inside the functions only: it and matplotlib (the legend) are the ``viewer`` extra.
"""

from __future__ import annotations

import base64
import json
import webbrowser
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aacmm_pin.data.campaign import Campaign, read_campaign
from aacmm_pin.data.output_claim import claim_output, input_paths
from aacmm_pin.data.output_file import write_text_file
from aacmm_pin.extras import require
from aacmm_pin.model.parameters import Parameters

if TYPE_CHECKING:
    from aacmm_pin.outputs._viewer_scene import Scene

Source = str | Path | Parameters


class View:
    """What :func:`view` made: the scene, and the live MeshCat server or the file it went to."""

    def __init__(self, scene: Scene, html: Path | None = None, visualizer: Any = None):
        self.scene = scene
        """The recorded scene (``scene.info`` summarises it)."""
        self.html = html
        """The static HTML file written, or None."""
        self._vis = visualizer

    @property
    def url(self) -> str | None:
        """URL of the live MeshCat page (localhost), or None without a server."""
        return None if self._vis is None else str(self._vis.url())

    @property
    def labels(self) -> list[str]:
        """Model labels in scene order; ``/meshcat/models/<label>`` holds each one's residuals."""
        return [m.label for m in self.scene.models]

    def _live(self) -> Any:
        if self._vis is None:
            raise RuntimeError("no live viewer: view(..., html=...) writes a file and starts no server")
        return self._vis

    def pose(self, q: np.ndarray) -> None:
        """Pose the arm of the live viewer at encoder readouts ``q``, shape (n_axes,), rad (maps applied).

        While the page plays its animation, the animation moves the arm too: pause it first
        (Controls > Animations > pause).
        """
        vis = self._live()
        for path, t in zip(self.scene.poser.paths, self.scene.poser.transforms(np.asarray(q, float))):
            vis[path].set_transform(t)

    def show_model(self, label: str) -> None:
        """Show the residuals of one model on the live viewer and hide the others."""
        if label not in self.labels:
            raise ValueError(f"label: choose from {', '.join(self.labels)}; got {label!r}")
        vis = self._live()
        for other in self.labels:
            vis[f"models/{other}"].set_property("visible", other == label)

    def close(self) -> None:
        """Stop the live MeshCat server (if any)."""
        if self._vis is not None:
            window, self._vis = self._vis.window, None
            window.server_proc.terminate()
            window.server_proc.wait(timeout=10)
            window.zmq_socket.close(linger=0)

    def __enter__(self) -> View:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def view(caldir_or_params: Source, campaign: Campaign | str | Path, *, html: str | Path | None = None,
         open_browser: bool = False, compare: Sequence[Source] = (), location: int | None = None,
         scale: float | None = None, max_postures: int = 200, force: bool = False) -> View:
    """Show a calibration's residuals on its campaign in MeshCat, live or as one HTML file.

    Args:
        caldir_or_params: calibration folder, ``parameters.json`` or :class:`Parameters`; its arm is
            drawn and its residuals are shown first.
        campaign: the campaign (or its folder) the calibrations are evaluated on.
        html: write the scene to this self-contained HTML file instead of starting a server.
        open_browser: open the page (the file, or the server's URL) in the default browser.
        compare: more calibrations to switch to (e.g. the ``dh`` model's CALDIR), hidden at first.
        location: R-Test location whose SPAT postures the animation steps through (default: first).
        scale: magnification of the deviations from each R-Test nest (1000: 1 µm drawn as 1 mm);
            None: the first calibration's RMS residual drawn ~20 mm long (1-2-5 steps).
        max_postures: most postures in the animation (evenly subsampled beyond).
        force: replace an existing ``html`` file (claimed before any work; never an input).

    Returns:
        The view; with a live server, call :meth:`View.close` (or use ``with``) to stop it.

    Raises:
        MissingExtraError: if the ``viewer`` extra (meshcat, matplotlib) is not installed (checked
            first).
        OutputExistsError: if ``html`` exists and not ``force``, or is one of the inputs.
        FileFormatError: for an unreadable calibration.
        CampaignFormatError: for a bad campaign folder.
        ValueError: for an unknown location or a non-positive scale.
    """
    require("viewer", "view")
    if html is not None:  # the file claimed before the work (and checked against the inputs)
        inputs = input_paths(
            campaigns=[campaign if isinstance(campaign, (str, Path)) else None],
            calibrations=[s for s in (caldir_or_params, *compare) if isinstance(s, (str, Path))])
        with claim_output(html, force, inputs, folder=False):
            scene = _scene(caldir_or_params, campaign, compare, location, scale, max_postures)
            path = write_html(scene, html, force, inputs)
        if open_browser:
            webbrowser.open(path.resolve().as_uri())
        return View(scene, html=path)
    scene = _scene(caldir_or_params, campaign, compare, location, scale, max_postures)
    vis = serve(scene)
    if open_browser:
        webbrowser.open(str(vis.url()), new=2)
    return View(scene, visualizer=vis)


def _scene(caldir_or_params: Source, campaign: Campaign | str | Path, compare: Sequence[Source],
           location: int | None, scale: float | None, max_postures: int) -> Scene:
    """Return the scene of :func:`view` (its arguments)."""
    from aacmm_pin.model.arm import load_arm
    from aacmm_pin.outputs._viewer_scene import build_scene, model_residuals
    from aacmm_pin.outputs.calibration_folder import read_calibration

    if not isinstance(campaign, Campaign):  # read against the arm: its columns, names and tools
        first = (caldir_or_params if isinstance(caldir_or_params, Parameters)
                 else read_calibration(caldir_or_params).parameters)
        campaign = read_campaign(campaign, arm=load_arm(first.arm))
    models = [model_residuals(s, campaign) for s in (caldir_or_params, *compare)]
    seen: dict[str, int] = {}
    for i, m in enumerate(models):
        seen[m.label] = seen.get(m.label, 0) + 1
        if seen[m.label] > 1:
            models[i] = replace(m, label=f"{m.label}_{seen[m.label]}")
    return build_scene(models, campaign, scale=scale, location=location, max_postures=max_postures)


def serve(scene: Scene) -> Any:
    """Start a MeshCat server on localhost, send it the scene, return the ``meshcat.Visualizer``.

    The server prints its URL; stop it with ``vis.window.server_proc.terminate()``.
    """
    from aacmm_pin.outputs._viewer_scene import import_meshcat

    vis = import_meshcat().Visualizer()
    try:
        socket = vis.window.zmq_socket
        for kind, path, data in scene.commands:
            socket.send_multipart([kind.encode(), path.encode(), data])
            socket.recv()
    except BaseException:
        vis.window.server_proc.terminate()
        raise
    return vis


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>{viewer_js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
window.aacmm_pin = {info};
(function () {{
  var commands = [{commands}];
  for (var i = 0; i < commands.length; i++) {{
    var text = atob(commands[i]), bytes = new Uint8Array(text.length);
    for (var j = 0; j < text.length; j++) bytes[j] = text.charCodeAt(j);
    viewer.handle_command_bytearray(bytes);
  }}
  window.aacmm_pin.ready = true;
}})();
</script>
</body>
</html>
"""


def static_html(scene: Scene, title: str = "aacmm_pin viewer") -> str:
    """Return the scene as one self-contained HTML page (MeshCat's viewer inlined, no network)."""
    from aacmm_pin.outputs._viewer_scene import import_meshcat

    meshcat = import_meshcat()
    viewer_js = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text("utf-8")
    commands = ",\n".join(f'"{base64.b64encode(data).decode("ascii")}"'
                          for _, _, data in scene.commands)
    info = json.dumps(scene.info).replace("</", "<\\/")
    return _PAGE.format(title=title, viewer_js=viewer_js, info=info, commands=commands)


def write_html(scene: Scene, path: str | Path, force: bool = False,
               inputs: Sequence[str | Path] = ()) -> Path:
    """Write :func:`static_html` to ``path`` (parent folders created) and return the path.

    Whole or not at all (:func:`~aacmm_pin.data.output_file.write_text_file`): an existing file is
    replaced only with ``force``, never when it is one of ``inputs``.
    """
    title = f"aacmm_pin: {', '.join(m.label for m in scene.models)}"
    return write_text_file(path, static_html(scene, title=title), force, inputs)
