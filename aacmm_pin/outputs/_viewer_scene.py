"""The MeshCat scene of :func:`aacmm_pin.outputs.viewer.view`, built once and recorded as packed commands.

The scene is drawn into :class:`Recorder`, a stand-in for meshcat's window that keeps every command
as the bytes meshcat would send. The same bytes go into the static HTML file and to a live MeshCat
server, so both show one scene. Everything is in the r-CS of each calibration, in metres; µm only
in the legend. Samples are batched: one Points, one LineSegments and one mesh of arrow heads per
model, whatever the number of samples.
"""

from __future__ import annotations

import io
import re
import textwrap
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from aacmm_pin.analyses.campaign_residuals import ModelResiduals, campaign_residuals
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.effects.parameters_file import check_extensions
from aacmm_pin.extras import require
from aacmm_pin.model.arm import Arm, load_arm, one_entry_per_axis
from aacmm_pin.model.encoder_map import correct_readouts
from aacmm_pin.model.parameters import Parameters, check_against_arm
from aacmm_pin.outputs.calibration_folder import read_calibration

ARM = "arm"
"""Scene path of the arm: ``/meshcat/arm/visuals/<URDF visual>``."""
CAMERA = "/Cameras/default/rotated/<object>"
"""Scene path of MeshCat's camera; objects below it (the legend panels) move with it."""
RING_UM = 10.0
"""Radius of the reference ring drawn around each R-Test nest, µm (magnified like the points)."""
SUBSTEPS = 3
"""Animation frames per SPAT posture (joint-space interpolation between postures)."""
_UM = 1e6


def import_meshcat() -> Any:
    """Import and return meshcat (0.3.2 warns of its own use of a deprecated pyzmq module).

    Raises:
        MissingExtraError: if the ``viewer`` extra (meshcat, matplotlib) is not installed.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "zmq.eventloop.ioloop is deprecated", DeprecationWarning)
        require("viewer", "the viewer")
        import meshcat
        import meshcat.animation
        import meshcat.geometry
    return meshcat


class Recorder:
    """A stand-in for ``meshcat.visualizer.ViewerWindow`` that records instead of sending."""

    server_proc = None

    def __init__(self) -> None:
        self.commands: list[tuple[str, str, bytes]] = []
        """(command type, scene path, msgpack bytes) in the order they were sent."""

    def send(self, command: Any) -> None:
        """Record one meshcat command (``SetObject``, ``SetTransform``, ...)."""
        import umsgpack

        data = command.lower()
        self.commands.append((data["type"], data["path"], umsgpack.packb(data)))


def model_residuals(source: str | Path | Parameters, campaign: Campaign, label: str | None = None
                    ) -> ModelResiduals:
    """Read a calibration (CALDIR, parameters.json or Parameters) and evaluate it on the campaign.

    The residuals are :func:`~aacmm_pin.analyses.campaign_residuals.campaign_residuals`'s; the
    label is made a scene path's name (other characters than ``A-Za-z0-9_.+-`` become ``_``).
    """
    offsets: dict[str, list[float]] = {}
    if isinstance(source, Parameters):
        params, default_label = source, "model"
    else:
        cal = read_calibration(source)
        params, offsets = cal.parameters, cal.nest_offsets_um
        default_label = cal.folder.resolve().name or "model"
    arm = load_arm(params.arm, error_frames=bool(params.dh))
    check_against_arm(params, arm)
    check_extensions(params, arm, None if isinstance(source, Parameters) else cal.file)
    name = re.sub(r"[^A-Za-z0-9_.+-]", "_", label or default_label)
    return campaign_residuals(params, arm, campaign, name, offsets)


class ArmPoser:
    """Placements of the arm's URDF visuals for encoder readouts (maps applied)."""

    def __init__(self, arm: Arm, params: Parameters):
        xml = one_entry_per_axis(arm.urdf_tree(params.dh, tools=params.tool_vectors(arm))).xml()
        self.model = pin.buildModelFromXML(xml)
        self.visual = pin.buildGeomFromUrdfString(self.model, xml, pin.GeometryType.VISUAL,
                                                  package_dirs=[str(Path(arm.source).parent)])
        self.data = self.model.createData()
        self.visual_data = pin.GeometryData(self.visual)
        self.maps = params.encoder_maps
        self.arm = arm
        self.paths = [f"{ARM}/visuals/{g.name}" for g in self.visual.geometryObjects]
        """Scene path of every visual, below ``/meshcat``."""

    def transforms(self, q_readout: np.ndarray) -> list[np.ndarray]:
        """Return the 4x4 placement of every visual (``paths`` order) for readouts, shape (n,), rad."""
        q = correct_readouts(np.atleast_2d(q_readout), self.maps)
        q = (self.arm.joint_angles(q) if self.arm.couplings else q)[0]  # coupled joints follow
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.visual, self.visual_data)
        out = []
        for geom, placement in zip(self.visual.geometryObjects, self.visual_data.oMg):
            t = placement.homogeneous.copy()
            t[:3, :3] = t[:3, :3] * np.asarray(geom.meshScale)  # as pinocchio's MeshcatVisualizer
            out.append(t)
        return out


@dataclass(eq=False)
class Scene:
    """A recorded scene and what it shows."""

    commands: list[tuple[str, str, bytes]]
    """(type, path, msgpack bytes) of every meshcat command, in order."""
    models: list[ModelResiduals]
    """The calibrations, the first one shown (its arm, the others' residuals hidden)."""
    poser: ArmPoser
    """Posing of the first calibration's arm."""
    scale: float
    """Magnification of deviations about each R-Test nest."""
    vmax: float
    """Top of the first model's colour scale of |residual|, m (each model has its own:
    :attr:`colour_tops`)."""
    location: int | None
    """R-Test location whose postures the animation steps through."""
    postures: np.ndarray
    """SPAT sample index of each animated posture (animation time t s shows posture ``int(t)``)."""
    coverage: dict[int, np.ndarray]
    """Axis -> SPAT samples per map bin (bins of ``step_deg`` from -180 deg), shape (n_bins,)."""
    info: dict[str, Any] = field(default_factory=dict)
    """JSON summary embedded in the static HTML (labels, RMS, scale, paths)."""
    colour_tops: list[float] = field(default_factory=list)
    """Top of each model's colour scale of |residual|, m (:func:`colour_top`), in model order."""


def _nice_ceil(value: float) -> float:
    """Return the smallest 1, 2, 5 x 10^k not below ``value`` (> 0)."""
    value = max(value, 1e-9)
    exp = np.floor(np.log10(value))
    for mantissa in (1.0, 2.0, 5.0, 10.0):
        if mantissa * 10 ** exp >= value * (1 - 1e-9):
            return float(mantissa * 10 ** exp)
    return float(10 ** (exp + 1))


def _colormap() -> Any:
    """Return the colour map of |residual|: plasma without its light yellow end (white background)."""
    from matplotlib import colormaps
    from matplotlib.colors import ListedColormap

    return ListedColormap(colormaps["plasma"](np.linspace(0.0, 0.85, 256)), name="plasma_dark")


def colour_top(errors: np.ndarray) -> float:
    """Return the top of a model's colour scale: its 99th-percentile |residual| rounded up, m.

    ``errors``: the model's |residual| per sample, shape (N,), m. Rounded up to 1, 2 or 5 x 10^k;
    each model has its own, so a good model's arrows span the colours as a poor model's do
    (one scale set by the worst model painted a good one's arrows all one colour).
    """
    return _nice_ceil(float(np.percentile(errors, 99)) if len(errors) else 1e-6)


def _colours(values: np.ndarray, vmax: float) -> np.ndarray:
    """Return the colours of ``values / vmax``, shape (N, 3), floats in 0-1."""
    return np.asarray(_colormap()(np.clip(values / vmax, 0.0, 1.0)))[:, :3]


def _frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return unit directions and two unit normals of each row of ``d``, shape (N, 3) each."""
    length = np.linalg.norm(d, axis=1, keepdims=True)
    u = np.where(length > 1e-12, d / np.where(length > 1e-12, length, 1.0), [0.0, 0.0, 1.0])
    helper = np.where(np.abs(u[:, 2:3]) > 0.9, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    v = np.cross(u, helper)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return u, v, np.cross(u, v)


def _arrow_heads(start: np.ndarray, end: np.ndarray, colour: np.ndarray) -> Any:
    """One mesh of triangular-pyramid heads at ``end`` pointing away from ``start`` (N arrows)."""
    import meshcat.geometry as mg

    d = end - start
    u, v, w = _frame(d)
    h = np.minimum(0.3 * np.linalg.norm(d, axis=1), 0.006)[:, None]
    base = end - h * u
    ang = 2 * np.pi * np.arange(3) / 3
    ring = [base + 0.45 * h * (np.cos(a) * v + np.sin(a) * w) for a in ang]
    vertices = np.stack([end, *ring], axis=1).reshape(-1, 3)
    first = 4 * np.arange(len(end))[:, None, None]
    faces = (first + np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1]])).reshape(-1, 3)
    return mg.TriangularMeshGeometry(vertices, faces, color=np.repeat(colour, 4, axis=0))


def _tubes(start: np.ndarray, end: np.ndarray, radius: float, colour: np.ndarray, sides: int = 8
           ) -> Any:
    """One mesh of N open tubes (prisms of ``sides`` sides) from ``start`` to ``end``."""
    import meshcat.geometry as mg

    _, v, w = _frame(end - start)
    ang = 2 * np.pi * np.arange(sides) / sides
    offsets = radius * (np.cos(ang)[None, :, None] * v[:, None] + np.sin(ang)[None, :, None] * w[:, None])
    vertices = np.concatenate([start[:, None] + offsets, end[:, None] + offsets], axis=1).reshape(-1, 3)
    k = np.arange(sides)
    quad = np.stack([np.stack([k, (k + 1) % sides, sides + k], 1),
                     np.stack([(k + 1) % sides, sides + (k + 1) % sides, sides + k], 1)], 1)
    faces = (2 * sides * np.arange(len(start))[:, None, None] + quad.reshape(1, -1, 3)).reshape(-1, 3)
    return mg.TriangularMeshGeometry(vertices, faces, color=np.repeat(colour, 2 * sides, axis=0))


def _points(positions: np.ndarray, colour: np.ndarray, size: float) -> Any:
    import meshcat.geometry as mg

    return mg.Points(mg.PointsGeometry(positions.T.astype(np.float32), colour.T.astype(np.float32)),
                     mg.PointsMaterial(size=size))


def _segments(start: np.ndarray, end: np.ndarray, colour: np.ndarray) -> Any:
    import meshcat.geometry as mg

    pos = np.stack([start, end], axis=1).reshape(-1, 3)
    col = np.repeat(colour, 2, axis=0)
    return mg.LineSegments(mg.PointsGeometry(pos.T.astype(np.float32), col.T.astype(np.float32)),
                           mg.LineBasicMaterial(vertexColors=True))


def _panel(vis: Any, path: str, png: tuple[bytes, float], width: float, left: float,
           top: float | None = None, bottom: float | None = None) -> None:
    """Put a PNG on a thin box 1 m in front of the camera, its corner at (left, top or bottom), m.

    Children of the camera move with it: the panel stays on screen (a head-up display). At 1 m, the
    visible height is 2 tan(75 deg / 2) = 1.53 m (MeshCat's camera), the width 2.05 m at 4:3.
    """
    import meshcat.geometry as mg

    data, aspect = png
    height = width * aspect
    y = top - height / 2 if top is not None else (bottom or 0.0) + height / 2
    material = mg.MeshBasicMaterial(map=mg.ImageTexture(mg.PngImage(data)), transparent=True,
                                    depthTest=False, side=0)
    node = vis[f"{CAMERA}/{path}"]
    node.set_object(mg.Box([width, height, 1e-4]), material)
    node.set_transform(_translation([left + width / 2, y, -1.0]))
    node["<object>"].set_property("renderOrder", 1000)


def _translation(p: Any) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = p
    return t


def _figure(width_in: float, height_in: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=200)
    FigureCanvasAgg(fig)
    fig.patch.set_facecolor((1, 1, 1, 0.88))
    return fig


def _png(fig: Any) -> tuple[bytes, float]:
    """Return the figure as PNG bytes and its height / width."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", facecolor=fig.get_facecolor())
    width, height = fig.get_size_inches()
    return buf.getvalue(), float(height / width)


def legend_png(scene: Scene) -> tuple[bytes, float]:
    """Return the legend panel: colour scale, magnification and each model's residuals, PNG."""
    return _png(_legend_figure(scene))


LEGEND_CHARS = 66
"""Longest legend line, characters: 5.6 pt text of at most this many fits the 3.3 in panel."""


def _legend_figure(scene: Scene) -> Any:
    """Build the figure of :func:`legend_png`; rows wrapped to :data:`LEGEND_CHARS`."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    rows = [f"deviations from each R-Test nest magnified {scene.scale:g}x (grey ring: {RING_UM:g} µm)",
            "arrow: predicted (dot) -> measured (dark dot); bar: its largest length error"]
    tops = scene.colour_tops or [scene.vmax] * len(scene.models)
    for m, top in zip(scene.models, tops):
        err = np.linalg.norm(m.residual, axis=1)
        text = (f"models/{m.label}: RMS {m.rms * _UM:.2f} µm/coord (nests as identified), "
                f"max {err.max() * _UM if len(err) else 0:.1f} µm")
        if m.validation is not None:
            text += f", bar RMS {m.validation.rms * _UM:.1f} µm"
        rows.append(text + f"; colours 0-{top * _UM:g} µm")
    if scene.location is not None:
        rows.append(f"Controls > Animations: time t s = posture t ({len(scene.postures)} SPAT "
                    f"postures, location {scene.location})")
    rows.append(f"{scene.models[0].label} shown; tick others in Controls > Scene > meshcat > models")
    lines = [line for row in rows for line in textwrap.wrap(row, LEGEND_CHARS,
                                                            subsequent_indent="   ")]
    height = 0.62 + 0.15 * len(lines)
    fig = _figure(3.3, height)
    cax = fig.add_axes((0.04, 1 - 0.34 / height, 0.92, 0.1 / height))
    bar = fig.colorbar(ScalarMappable(Normalize(0, 1), _colormap()), cax=cax,
                       orientation="horizontal")
    bar.set_ticks([0.0, 0.5, 1.0], labels=["0", "half", "top"])
    bar.ax.tick_params(labelsize=6, length=2, pad=1)
    cax.set_title("|residual|, predicted -> measured sphere centre (each model's own scale: "
                  "its row)", fontsize=5.6, pad=3)
    for i, text in enumerate(lines):
        fig.text(0.03, 1 - (0.56 + 0.15 * i) / height, text, fontsize=5.6, va="top")
    return fig


def coverage_png(scene: Scene, lengthbar_q: np.ndarray | None, limits: np.ndarray
                 ) -> tuple[bytes, float]:
    """Return the coverage panel: for every axis the readout bins the SPATs (and the bar) visited."""
    counts = np.array([scene.coverage[a] for a in sorted(scene.coverage)], dtype=float)
    n_axes, n_bins = counts.shape
    step = 360.0 / n_bins
    centres = -180.0 + step * (np.arange(n_bins) + 0.5)
    image = np.ones((n_axes, n_bins, 4))
    blue = np.array([0.0, 0.447, 0.698])
    share = counts / max(counts.max(), 1.0)
    seen = counts > 0
    image[seen, :3] = 1 - (0.3 + 0.7 * share[seen])[:, None] * (1 - blue)
    outside = (np.radians(centres) < limits[:, :1]) | (np.radians(centres) > limits[:, 1:])
    image[outside & ~seen, :3] = 0.8
    fig = _figure(3.3, 0.3 + 0.14 * n_axes)
    ax = fig.add_axes((0.09, 0.13, 0.72, 0.76))
    ax.imshow(image, aspect="auto", extent=(-180, 180, n_axes + 0.5, 0.5), interpolation="nearest")
    if lengthbar_q is not None:
        deg = (np.degrees(lengthbar_q) + 180.0) % 360.0 - 180.0
        for a in range(n_axes):
            ax.plot(deg[:, a], np.full(len(deg), a + 1.32), "|", color="#e69f00", markersize=2.5, mew=0.8)
    ax.set_yticks(np.arange(1, n_axes + 1), [f"A{a}" for a in range(1, n_axes + 1)], fontsize=5.5)
    ax.set_xticks([-180, -90, 0, 90, 180], ["-180", "-90", "0", "90", "180 deg"], fontsize=5.5)
    ax.tick_params(length=1.5, pad=1)
    for a in range(n_axes):
        ax.text(1.02, 1 - (a + 0.5) / n_axes, f"{seen[a].sum() * step:.0f}° seen", fontsize=5.5,
                transform=ax.transAxes, va="center")
    ax.set_title("readouts visited: blue SPAT (darker = more), orange bar, grey outside limits",
                 fontsize=5.5, pad=2)
    return _png(fig)


def coverage_counts(q: np.ndarray, step_deg: float) -> dict[int, np.ndarray]:
    """Return axis -> number of readouts per ``step_deg`` bin from -180 deg, for readouts (N, n)."""
    n_bins = int(round(360 / step_deg))
    wrapped = (np.degrees(np.asarray(q)) + 180.0) % 360.0  # degrees: readouts are written in degrees
    bins = np.floor(wrapped / step_deg + 1e-9).astype(int) % n_bins
    return {a + 1: np.bincount(bins[:, a], minlength=n_bins) for a in range(q.shape[1])}


def _animated_postures(campaign: Campaign, location: int | None, max_postures: int
                       ) -> tuple[int | None, np.ndarray]:
    """Return the location to animate and the SPAT sample indices of its postures (subsampled)."""
    spat = campaign.spat
    if spat is None:
        return None, np.zeros(0, dtype=int)
    ids = campaign.location_ids
    location = ids[0] if location is None else int(location)
    if location not in ids:
        raise ValueError(f"location: the campaign has R-Test locations {list(ids)}, not {location}")
    index = np.flatnonzero(spat.location == location)
    keep = np.unique(np.linspace(0, len(index) - 1, min(len(index), max_postures)).round().astype(int))
    return location, index[keep]


def _magnified(model: ModelResiduals, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Return predicted and measured centres with their deviation from the nest magnified."""
    return (model.nest + scale * (model.predicted - model.nest),
            model.nest + scale * (model.measured - model.nest))


def _draw_campaign(vis: Any, campaign: Campaign, first: ModelResiduals, scale: float) -> None:
    """Draw the R-Test nests (with a magnified reference ring) and the bar sockets."""
    import meshcat.geometry as mg

    rot, trans = first.params.rotation(), first.params.translation
    ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    ring = RING_UM * 1e-6 * scale * np.stack([np.cos(ang), np.sin(ang), 0 * ang])
    for loc, p_mt in campaign.locations.items():
        node = vis[f"campaign/rtest/{loc}"]
        node.set_transform(_translation((p_mt - trans) @ rot))
        node["nest"].set_object(mg.Box([0.003, 0.003, 0.003]), mg.MeshLambertMaterial(color=0x606060))
        node["ring"].set_object(mg.LineLoop(mg.PointsGeometry(ring.astype(np.float32)),
                                            mg.LineBasicMaterial(color=0x404040)))
    for (placement, socket), p in first.sockets.items():
        node = vis[f"campaign/bar/{placement}/{socket}"]
        node.set_object(mg.Sphere(0.006), mg.MeshLambertMaterial(color=0xb0b0b0))
        node.set_transform(_translation(p))


def _draw_model(vis: Any, model: ModelResiduals, scale: float, vmax: float) -> list[str]:
    """Draw one model's residuals and bar errors below ``models/<label>``; return the paths."""
    import meshcat.geometry as mg

    node, paths = vis[f"models/{model.label}"], []
    err = np.linalg.norm(model.residual, axis=1)
    if len(err):
        pred, meas = _magnified(model, scale)
        colour = _colours(err, vmax)
        node["predicted"].set_object(_points(pred, colour, 0.004))
        node["measured"].set_object(_points(meas, np.full_like(colour, 0.2), 0.002))
        node["residuals"].set_object(_segments(pred, meas, colour))
        node["heads"].set_object(_arrow_heads(pred, meas, colour), mg.MeshBasicMaterial(vertexColors=True))
        paths += ["predicted", "measured", "residuals", "heads"]
    if model.validation is not None and model.sockets:
        starts, ends, bar_err = [], [], []
        for placement, errors in zip(model.validation.placements, model.validation.errors):
            here = [p for (k, _), p in model.sockets.items() if k == placement]
            a, b = divmod(int(np.argmax([np.linalg.norm(u - v) for u in here for v in here])), len(here))
            starts.append(here[a])
            ends.append(here[b])
            bar_err.append(np.nanmax(np.abs(errors)))
        node["bar"].set_object(_tubes(np.array(starts), np.array(ends), 0.003,
                                      _colours(np.array(bar_err), vmax)),
                               mg.MeshLambertMaterial(vertexColors=True))
        paths.append("bar")
    return [f"/meshcat/models/{model.label}/{p}" for p in paths]


def _animate(vis: Any, scene: Scene, q: np.ndarray) -> None:
    """Add the animation through the postures ``scene.postures`` (readouts ``q``, (N, n) rad)."""
    from meshcat.animation import Animation

    anim = Animation(default_framerate=SUBSTEPS)
    pred, meas = _magnified(scene.models[0], scene.scale)
    poser, postures = scene.poser, scene.postures
    for i, sample in enumerate(postures):
        frame = anim.at_frame(vis, SUBSTEPS * i)
        frame["current/predicted"].set_transform(_translation(pred[sample]))
        frame["current/measured"].set_transform(_translation(meas[sample]))
        for k in range(1 if i == len(postures) - 1 else SUBSTEPS):  # joint-space in-betweens
            q_k = q[sample] if k == 0 else q[sample] + k / SUBSTEPS * (q[postures[i + 1]] - q[sample])
            frame = anim.at_frame(vis, SUBSTEPS * i + k)
            for path, t in zip(poser.paths, poser.transforms(q_k)):
                frame[path].set_transform(t)
    vis["current/predicted"].set_transform(_translation(pred[postures[0]]))
    vis["current/measured"].set_transform(_translation(meas[postures[0]]))
    vis.set_animation(anim, play=True, repetitions=1)


ARROW_M = 0.02
"""Default magnification: the first model's RMS residual is drawn about this long, m."""


def auto_scale(model: ModelResiduals) -> float:
    """Return the magnification that draws the model's RMS residual ~ARROW_M long.

    Rounded down to 1, 2 or 5 times a power of ten and kept within 100..100000: a DH fit (26 um)
    gets 500x, a proposed fit (1.9 um) 10000x, so either model's arrows show at the default view.
    """
    raw = ARROW_M / max(model.rms, 1e-9)
    power = 10.0 ** np.floor(np.log10(raw))
    step = max(m for m in (1.0, 2.0, 5.0) if m * power <= raw)
    return float(np.clip(step * power, 100.0, 1e5))


def build_scene(models: list[ModelResiduals], campaign: Campaign, *, scale: float | None = None,
                location: int | None = None, max_postures: int = 200,
                camera: tuple[float, float, float] = (0.6, -0.8, 0.55)) -> Scene:
    """Draw the arm, the campaign and every model's residuals into a recorded scene.

    Args:
        models: calibrations evaluated on the campaign; the first is shown, the others hidden.
        campaign: the campaign (SPAT and/or length bar).
        scale: magnification of the deviations about each R-Test nest (points and arrows);
            None: :func:`auto_scale` of the first model.
        location: R-Test location whose SPAT postures the animation steps through (default: first).
        max_postures: most postures in the animation (evenly subsampled beyond).
        camera: camera position from the view centre (half-way from the base to the nests), m.
    """
    meshcat = import_meshcat()
    mg = meshcat.geometry
    from pinocchio.visualize import MeshcatVisualizer

    if not models:
        raise ValueError("models: give at least one calibration")
    scale = auto_scale(models[0]) if scale is None else scale
    if not scale > 0:
        raise ValueError(f"scale: must be positive, got {scale}")
    first = models[0]
    recorder = Recorder()
    vis = meshcat.Visualizer(window=recorder)
    poser = ArmPoser(first.arm, first.params)
    viz = MeshcatVisualizer(poser.model, None, poser.visual)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName=ARM)

    errors = [np.linalg.norm(m.residual, axis=1) for m in models]
    tops = [colour_top(e) for e in errors]
    location, postures = _animated_postures(campaign, location, max_postures)
    q = campaign.spat.q if campaign.spat is not None else np.zeros((0, first.arm.n_axes))
    scene = Scene(recorder.commands, models, poser, scale, tops[0], location, postures,
                  coverage_counts(q, first.params.step_deg), colour_tops=tops)

    _draw_campaign(vis, campaign, first, scale)
    paths = []
    for i, (model, top) in enumerate(zip(models, tops)):
        paths += _draw_model(vis, model, scale, top)
        if i > 0:
            vis[f"models/{model.label}"].set_property("visible", False)
    for name, (radius, colour) in {"predicted": (0.0035, 0xd55e00),
                                   "measured": (0.0025, 0x202020)}.items():
        vis[f"current/{name}"].set_object(mg.Sphere(radius), mg.MeshLambertMaterial(color=colour))
    q0 = q[postures[0]] if len(postures) else np.zeros(first.arm.n_axes)
    for path, t in zip(poser.paths, poser.transforms(q0)):
        vis[path].set_transform(t)
    if len(postures):
        _animate(vis, scene, q)

    rot, trans = first.params.rotation(), first.params.translation
    nests = [(p - trans) @ rot for p in campaign.locations.values()]
    centre = 0.5 * np.mean(nests, axis=0) * [1, 1, 0] if nests else np.zeros(3)
    vis.set_transform(_translation(-centre))  # the orbit centre (origin) between base and nests
    vis["/Axes"].set_property("visible", False)
    vis["/Grid"].set_property("visible", False)
    vis["/Background"].set_property("top_color", [1.0, 1.0, 1.0])
    vis["/Background"].set_property("bottom_color", [0.82, 0.84, 0.87])
    x, y, z = camera
    vis[CAMERA].set_property("position", [x, z, -y])
    _panel(vis, "legend", legend_png(scene), 0.9, left=-1.0, top=0.75)
    bar_q = campaign.lengthbar.q if campaign.lengthbar is not None else None
    _panel(vis, "coverage", coverage_png(scene, bar_q, first.arm.joint_limits), 0.9, left=-1.0,
           bottom=-0.75)
    scene.info = {
        "models": [{"label": m.label, "rms_um": m.rms * _UM, "n_samples": int(len(e)),
                    "max_um": float(e.max() * _UM) if len(e) else 0.0,
                    "colour_top_um": top * _UM,
                    "bar_rms_um": None if m.validation is None else m.validation.rms * _UM}
                   for m, e, top in zip(models, errors, tops)],
        "scale": scale, "vmax_um": tops[0] * _UM, "location": location,
        "postures": postures.tolist(), "substeps": SUBSTEPS, "view_centre": centre.tolist(),
        "arm_paths": [f"/meshcat/{p}" for p in poser.paths], "residual_paths": paths,
    }
    return scene
