r"""The compact URDF: every error frame folded into the joint origins, the user's names only.

An arm's URDF with its error frames set to values (:meth:`aacmm_pin.model.arm.Arm.urdf_tree`)
holds each DH error as a fixed joint and a link (``dx21`` -> ``dx21_frame``): exact, but a robotics
stack sees them as about thirty extra TF frames. :func:`compact_urdf` removes every error frame
(a fixed joint named as :data:`~aacmm_pin.model.arm.ERROR_FRAME_PATTERN` says) and its child link;
a joint whose parent was that link gets the error frame's parent link and the origin
:math:`T_{error} \, T_{origin}`, written to full double precision, so that Pinocchio builds the same
kinematics to rounding (about 1e-15 m). The ``tool`` / ``tool_<name>`` joints are not error frames:
they stay. Everything else the user wrote stays as written (visuals, meshes, materials, limits,
transmissions, comments).

An error frame's child link is empty in aacmm_pin's own URDFs (``<link name="dx21_frame"/>``). One
that carries ``<visual>``, ``<collision>`` or ``<inertial>`` elements hands them to the error
frame's parent link, their origins composed with the error frame's; two inertials are combined
(mass, centre of mass, inertia about the new centre of mass).

Units as in URDF: m, rad, kg, kg m^2.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pinocchio as pin
from lxml import etree

from aacmm_pin.model.arm import ERROR_FRAME_PATTERN
from aacmm_pin.model.urdf_tree import UrdfTree, number_text, origin_matrix

__all__ = ["compact_urdf", "error_frame_joints"]


def error_frame_joints(tree: UrdfTree) -> list[str]:
    """Return the names of the tree's error frames (fixed joints named like ``dx21``), file order."""
    return [j.name for j in tree.joints() if j.type == "fixed" and ERROR_FRAME_PATTERN.match(j.name)]


def compact_urdf(tree: UrdfTree, names: Iterable[str] | None = None) -> UrdfTree:
    """Return a copy of the tree with the error frames folded into the joint origins.

    Args:
        tree: a URDF tree, e.g. :meth:`~aacmm_pin.model.arm.Arm.urdf_tree` with the error
            frames and tool vectors set to the calibrated values (m, rad).
        names: the error-frame joints to fold (default: :func:`error_frame_joints`).

    Returns:
        The compact tree: no error-frame joint and no error-frame link; every other joint and link
        as in ``tree`` (the joints after an error frame with composed origins).

    Raises:
        ValueError: if ``names`` names a joint that is not a fixed joint of the tree.
    """
    out = tree.copy()
    fold = list(error_frame_joints(out) if names is None else names)
    fixed = {j.name for j in out.joints() if j.type == "fixed"}
    if bad := [n for n in fold if n not in fixed]:
        raise ValueError(f"names: not fixed joints of the URDF: {', '.join(bad)}")
    for name in fold:
        _fold(out, name)
    return out


def _element(root: etree._Element, tag: str, name: str) -> etree._Element:
    for element in root.findall(tag):
        if element.get("name") == name:
            return element
    raise KeyError(name)


def _origin_of(element: etree._Element) -> np.ndarray:
    """The 4x4 origin of a joint, visual, collision or inertial element (identity when absent)."""
    node = element.find("origin")
    if node is None:
        return np.eye(4)

    def values(key: str) -> np.ndarray:
        text = node.get(key)
        return np.zeros(3) if text is None else np.array([float(v) for v in text.split()])

    return origin_matrix(values("xyz"), values("rpy"))


def _set_origin(element: etree._Element, origin: np.ndarray, keep_rotation: bool = False) -> None:
    """Write an origin (4x4) into an element, to full precision; ``keep_rotation``: rpy as written."""
    node = element.find("origin")
    if node is None:
        node = etree.Element("origin")
        element.insert(0, node)
    node.set("xyz", number_text(origin[:3, 3]))
    if not keep_rotation:
        node.set("rpy", number_text(pin.rpy.matrixToRpy(np.asarray(origin[:3, :3], float))))


def _fold(tree: UrdfTree, name: str) -> None:
    """Fold one error frame (fixed joint ``name``) into the joints after it and its parent link."""
    root = tree.root
    joint = _element(root, "joint", name)
    parent = str(joint.find("parent").get("link"))  # UrdfTree.joints checked both ends
    child = str(joint.find("child").get("link"))
    t_error = _origin_of(joint)
    pure_translation = bool(np.array_equal(t_error[:3, :3], np.eye(3)))
    for other in root.findall("joint"):
        node = other.find("parent")
        if other is joint or node is None or node.get("link") != child:
            continue
        node.set("link", parent)
        _set_origin(other, t_error @ _origin_of(other), keep_rotation=pure_translation)
    link = _element(root, "link", child)
    _move_contents(link, _element(root, "link", parent), t_error)
    root.remove(joint)
    root.remove(link)


def _move_contents(link: etree._Element, parent: etree._Element, t_error: np.ndarray) -> None:
    """Hand a link's visuals, collisions and inertial to its parent link, origins composed."""
    for tag in ("visual", "collision"):
        for element in link.findall(tag):
            _set_origin(element, t_error @ _origin_of(element))
            parent.append(element)
    inertial = link.find("inertial")
    if inertial is None:
        return
    moved = _inertia(inertial).se3Action(pin.SE3(t_error))
    own = parent.find("inertial")
    total = moved if own is None else moved + _inertia(own)
    if own is not None:
        parent.remove(own)
    parent.insert(0, _inertial_element(total))


def _inertia(element: etree._Element) -> pin.Inertia:
    """A URDF ``<inertial>`` as Pinocchio's inertia (in its link's frame)."""
    mass_node = element.find("mass")
    mass = 0.0 if mass_node is None else float(mass_node.get("value", "0"))
    node = element.find("inertia")
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {k: 0.0 if node is None else float(node.get(k, "0")) for k in keys}
    about_com = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                          [v["ixz"], v["iyz"], v["izz"]]])
    origin = _origin_of(element)  # the centre of mass and the inertia's axes
    rot = origin[:3, :3]
    return pin.Inertia(mass, origin[:3, 3], rot @ about_com @ rot.T)


def _inertial_element(inertia: pin.Inertia) -> etree._Element:
    """An ``<inertial>`` element: mass, centre of mass, inertia about it in the link's axes."""
    element = etree.Element("inertial")
    etree.SubElement(element, "origin", xyz=number_text(inertia.lever), rpy="0 0 0")
    etree.SubElement(element, "mass", value=number_text([inertia.mass]))
    i = np.asarray(inertia.inertia)
    etree.SubElement(element, "inertia", ixx=repr(float(i[0, 0])), ixy=repr(float(i[0, 1])),
                     ixz=repr(float(i[0, 2])), iyy=repr(float(i[1, 1])),
                     iyz=repr(float(i[1, 2])), izz=repr(float(i[2, 2])))
    return element
