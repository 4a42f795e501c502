"""Resource paths of a URDF written elsewhere: :func:`rebase_resources`.

A URDF names its meshes and textures (``<mesh filename="meshes/upper_arm.stl"/>``,
``<texture filename=...>``) relative to its own folder. ``calibrated.urdf`` is the arm's URDF
written into a calibration folder, so each relative path is rewritten to reach the same file from
there (``../../arm/meshes/upper_arm.stl``); a ``package://``, ``file://`` or other URI and an
absolute path mean the same from anywhere and are left as written, and so is a ``filename`` of any
other element (a Gazebo ``<plugin filename="libgazebo_ros_control.so">`` names a library on the
plugin path, not a file beside the URDF).
"""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath

from lxml import etree

RESOURCE_TAGS = ("mesh", "texture")
"""The URDF elements whose ``filename`` names a file (the URDF specification's two)."""


def rebase_resources(root: etree._Element, source_dir: str | Path, out_dir: str | Path) -> int:
    """Rewrite, in place, the relative ``filename`` paths of a URDF so they hold from ``out_dir``.

    Args:
        root: the URDF's ``<robot>`` element (of a copy: :meth:`aacmm_pin.model.arm.Arm.urdf_tree`).
        source_dir: the folder of the URDF the tree was read from (what its paths are relative to).
        out_dir: the folder the URDF is written to.

    Returns:
        How many paths were rewritten (relative to ``out_dir``, in ``/`` form).
    """
    source = Path(source_dir).absolute()
    out = Path(out_dir).absolute()
    count = 0
    for element in root.iter(*RESOURCE_TAGS):
        value = element.get("filename")
        if not value or "://" in value or value.startswith("file:") or os.path.isabs(value):
            continue
        rebased = PurePosixPath(*Path(os.path.relpath(source / value, out)).parts).as_posix()
        if rebased != value:
            element.set("filename", rebased)
            count += 1
    return count
