"""The fitted instrument frames of a calibration: written to ``report.json``, read by ``predict --frame``.

A points campaign is measured in the frames of its instruments (``group`` of ``points.csv``).
Without SPAT the lowest group's frame is the calibration's MT-CS (``base_to_mt`` of
``parameters.json``); every other group (all of them beside SPAT) has a frame of its own, six
unknowns of the identification. :func:`instrument_frames` writes each one as the rigid transform
``p_mt = R p + t`` of a point ``p`` measured in it; :func:`to_instrument_frame` maps predicted
MT-CS points into a group's frame, so that they compare with that instrument's data directly.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from aacmm_pin.errors import AacmmError
from aacmm_pin.units import MM

if TYPE_CHECKING:  # predict reads frames and needs no fit
    from aacmm_pin.fit.identification_result import Calibration

FRAMES_KEY = "instrument_frames"
"""Key of ``report.json``: instrument group -> ``{"rotation": 3x3, "translation_mm": [x, y, z]}``,
the transform of a point measured in that group's frame into the calibration's MT-CS."""


def instrument_frames(cal: Calibration) -> dict[str, dict[str, list[Any]]]:
    """Return every instrument group's fitted frame, as ``report.json`` holds it (:data:`FRAMES_KEY`).

    Empty for a calibration without points. The main group (without SPAT: the lowest) is the
    identity: its points were fitted in the MT-CS itself.
    """
    from aacmm_pin.fit.unknowns import FrameKey

    if "points" not in cal.inputs:
        return {}
    out: dict[str, dict[str, list[Any]]] = {}
    if "spat" not in cal.inputs:
        nest = cal.problem.nuisance.nest
        point = np.ones(len(cal.location), dtype=bool) if nest is None else nest < 0
        if point.any():
            main = int(np.min(cal.location[point]))
            out[str(main)] = {"rotation": np.eye(3).tolist(), "translation_mm": [0.0, 0.0, 0.0]}
    groups = list(dict.fromkeys(k.group for k in cal.nuisance_keys if isinstance(k, FrameKey)))
    if groups:
        rot, trans = cal.problem.frames(cal.x)
        for g, r, t in zip(groups, rot, trans):
            out[str(g)] = {"rotation": r.tolist(), "translation_mm": (t / MM).tolist()}
    return out


def frame_of(report: dict[str, Any] | None, group: int, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Return group ``group``'s frame ``(R (3, 3), t (3,) m)`` from a calibration's report.

    Args:
        report: the calibration's ``report.json`` content, or None.
        group: the instrument group (``group`` of ``points.csv``).
        where: the calibration folder, named in errors.

    Raises:
        AacmmError: one line, when the report has no fitted frame of that group (not fitted to
            points, an older report, another group) or holds a malformed one.
    """
    frames = (report or {}).get(FRAMES_KEY)
    if not isinstance(frames, dict) or not frames:
        raise AacmmError(f"--frame {group}: {where} holds no fitted instrument frame (report.json "
                         f"'{FRAMES_KEY}'): identify it again from a campaign with points.csv")
    entry = frames.get(str(group))
    if entry is None:
        raise AacmmError(f"--frame {group}: {where} has no instrument group {group}; its groups: "
                         f"{', '.join(sorted(frames, key=lambda k: (len(k), k)))}")
    try:
        rot = np.array(entry["rotation"], dtype=float)
        trans = np.array(entry["translation_mm"], dtype=float) * MM
    except (KeyError, TypeError, ValueError):
        rot = trans = np.zeros(0)
    if rot.shape != (3, 3) or trans.shape != (3,) or not (np.all(np.isfinite(rot))
                                                          and np.all(np.isfinite(trans))) \
            or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-9):
        raise AacmmError(f"--frame {group}: {where}: report.json '{FRAMES_KEY}' of group {group} "
                         "is not a rotation (3x3) and a translation_mm (3)")
    return rot, trans


def to_instrument_frame(points_mt: np.ndarray, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Return MT-CS points (N, 3), m, in an instrument frame ``p_mt = R p + t``: ``R^T (p_mt - t)``."""
    out: np.ndarray = (np.asarray(points_mt, dtype=float) - trans) @ rot
    return out
