r"""A URDF as its XML tree: the joints aacmm_pin reads from it and the edits it makes to a copy.

The arm's models and the exported ``calibrated.urdf`` are the user's own URDF with a few joints
edited (an error frame's or a tool's origin set, joints made fixed or 1-DOF, joints and links
added), so every other element and comment in the file is kept: visuals, meshes, materials,
inertias, ``<transmission>``, ``<gazebo>``, ``<ros2_control>`` (lxml writes them back: a DOCTYPE
is dropped, CDATA and character references come back as plain text). lxml parses strictly (no recovery
from broken XML, no entities, no network) and remembers each element's line, so that a bad joint
is named with its file and line. Pinocchio builds the models from the edited text; it is the
reference for the kinematics, this module only reads the joints' names, links, origins, axes and
limits that :mod:`aacmm_pin.model.arm` needs to find the axes, error frames and tools.

Units as in URDF: m and rad.
"""

from __future__ import annotations

import copy
import hashlib
import math
import re
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from lxml import etree

from aacmm_pin.errors import ArmModelError

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
"""The joint types of the URDF specification."""
MAX_CHAIN_JOINTS = 2000
"""Most joints on one chain from the root link (error frames added in memory included).

Pinocchio's URDF parser recurses once per joint: deeper chains overflow its stack and end the
process with SIGSEGV (measured on Linux, 8 MiB stack: 4,000 fixed joints crash; 3,000 fixed and 2,500
revolute joints pass). An arm has
tens (the default AACMM 50 with its error frames)."""


@dataclass(frozen=True, eq=False)
class Joint:
    """One ``<joint>`` element as read (its values; edits go through :class:`UrdfTree`)."""

    name: str
    type: str
    """One of :data:`JOINT_TYPES`."""
    parent: str
    """Parent link name."""
    child: str
    """Child link name."""
    origin: np.ndarray
    """Joint origin (parent link frame -> joint frame), 4x4 homogeneous transform, m."""
    axis: np.ndarray
    """Unit axis in the joint frame, shape (3,) (the URDF default x when absent)."""
    lower: float | None
    """Lower limit (rad or m), None when the joint has no ``<limit lower=...>``."""
    upper: float | None
    """Upper limit (rad or m), None when the joint has no ``<limit upper=...>``."""
    line: int | None
    """Line of the ``<joint>`` element in its file (None for a joint built in memory)."""
    mimic: tuple[str, float, float] | None = None
    """``<mimic joint multiplier offset>``: (the joint it follows, multiplier, offset in rad),
    multiplier 1 and offset 0 where not written; None without a ``<mimic>``."""


_READ: OrderedDict[tuple[str, bytes, tuple[int | None, ...]], tuple[Joint, ...]] = OrderedDict()
"""Joints read, by path, the tree's text and its joints' lines (:meth:`UrdfTree.joints`)."""
_READ_LOCK = threading.Lock()
_READ_KEPT = 32
"""Most trees whose joints are remembered (the least recently read are forgotten)."""

NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
"""A number as URDF parsers read it (not Python's ``float``: ``1_0``, ``inf``, other digits)."""


def _numbers(text: str | None, count: int, what: str, where: str, path: Path | str
             ) -> np.ndarray:
    """Parse ``count`` finite numbers separated by spaces (None: zeros)."""
    if text is None:
        return np.zeros(count)
    parts = [p for p in text.split(" ") if p]
    good = len(parts) == count and all(NUMBER.fullmatch(p) for p in parts)
    values = [float(p) for p in parts] if good else []
    if len(values) != count or not all(map(math.isfinite, values)):
        raise ArmModelError(path, f"{where}: {what}: {count} finite numbers expected, got {text!r}")
    return np.array(values)


def _number(element: etree._Element, attribute: str, where: str, path: Path | str) -> float | None:
    text = element.get(attribute)
    return None if text is None else float(_numbers(text, 1, attribute, where, path)[0])


def origin_matrix(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    """Return the 4x4 transform of a URDF origin: translation xyz (m), fixed-axis roll-pitch-yaw (rad)."""
    out = np.eye(4)
    out[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    out[:3, 3] = xyz
    return out


def number_text(values: np.ndarray | list[float]) -> str:
    """Numbers as URDF attribute text, each to full double precision (``repr``: 17 digits at most)."""
    return " ".join(repr(float(v) + 0.0) for v in values)


class UrdfTree:
    """A parsed URDF (lxml tree) with its joints read; edits change this tree only.

    Use :func:`read_urdf` to make one, :meth:`copy` before editing a shared one.
    """

    def __init__(self, tree: etree._ElementTree, path: Path | str):
        self._tree = tree
        self.path = path
        """Where the URDF came from (for messages)."""
        self.root: etree._Element = tree.getroot()
        if self.root.tag != "robot":
            raise ArmModelError(path, f"line {self.root.sourceline}: the root element is "
                                      f"<{self.root.tag}>, a URDF's is <robot>")

    def copy(self) -> UrdfTree:
        """Return a deep copy to edit."""
        out = copy.copy(self)
        out._tree = copy.deepcopy(self._tree)
        out.root = out._tree.getroot()
        return out

    # ------------------------------------------------------------------ reading
    @property
    def links(self) -> list[str]:
        """Names of the ``<link>`` elements, in file order."""
        return [str(e.get("name")) for e in self.root.findall("link")]

    def joints(self) -> list[Joint]:
        """Read every ``<joint>`` element, in file order.

        A tree read before with the same text, joint lines and path gives the same joints without
        reading them again (an arm's models read one tree many times: 11 reads of ~7 ms each in
        one ``identify`` of the UR5; the text is compared whole, so an edit made through
        :attr:`root` reads afresh). The joints' arrays are read-only.

        Raises:
            ArmModelError: for a joint without name, type, parent or child, an unknown type,
                a duplicate name, a link that is not declared, or numbers that do not parse
                (naming the file and the joint's line).
        """
        key = (str(self.path), hashlib.blake2b(etree.tostring(self.root)).digest(),
               tuple(e.sourceline for e in self.root.iterfind("joint")))
        with _READ_LOCK:  # threads of a pool may read trees at once
            known = _READ.get(key)
            if known is not None:
                _READ.move_to_end(key)
        if known is None:
            known = tuple(self._read_joints())
            with _READ_LOCK:
                _READ[key] = known
                while len(_READ) > _READ_KEPT:
                    _READ.popitem(last=False)
        return list(known)

    def _read_joints(self) -> list[Joint]:
        """Read every ``<joint>`` element (:meth:`joints`, without its memory of earlier reads)."""
        path, links, out = self.path, set(self.links), []
        names: set[str] = set()
        for element in self.root.findall("joint"):
            where = f"line {element.sourceline}: joint '{element.get('name')}'"
            name, kind = element.get("name"), element.get("type")
            if not name:
                raise ArmModelError(path, f"line {element.sourceline}: a <joint> without a name")
            if name in names:
                raise ArmModelError(path, f"{where}: a second joint of this name")
            names.add(name)
            if kind not in JOINT_TYPES:
                raise ArmModelError(path, f"{where}: type {kind!r}; a URDF joint is one of "
                                          f"{', '.join(JOINT_TYPES)}")
            ends = {}
            for end in ("parent", "child"):
                node = element.find(end)
                link = None if node is None else node.get("link")
                if not link:
                    raise ArmModelError(path, f"{where}: no <{end} link=\"...\"/>")
                if link not in links:
                    raise ArmModelError(path, f"{where}: {end} link '{link}' is not declared "
                                              "as a <link>")
                ends[end] = link
            node = element.find("origin")
            origin = np.eye(4) if node is None else origin_matrix(
                _numbers(node.get("xyz"), 3, "origin xyz", where, path),
                _numbers(node.get("rpy"), 3, "origin rpy", where, path))
            node = element.find("axis")
            axis = np.array([1.0, 0, 0]) if node is None else _numbers(
                node.get("xyz"), 3, "axis xyz", where, path)
            if kind != "fixed" and not np.linalg.norm(axis) > 0:
                raise ArmModelError(path, f"{where}: axis xyz is zero")
            axis = axis / (np.linalg.norm(axis) or 1.0)
            node = element.find("limit")
            lower = None if node is None else _number(node, "lower", where, path)
            upper = None if node is None else _number(node, "upper", where, path)
            mimics = element.findall("mimic")
            node, mimic = (mimics[0] if mimics else None), None
            if len(mimics) > 1:
                raise ArmModelError(path, f"line {mimics[1].sourceline}: joint '{name}': a second "
                                          f"<mimic> (the first is on line {mimics[0].sourceline}); a "
                                          "joint follows one other joint")
            if node is not None and kind == "fixed":
                raise ArmModelError(path, f"line {node.sourceline}: joint '{name}': a <mimic> on a "
                                          "fixed joint, which has no angle to couple")
            if node is not None:
                if not node.get("joint"):
                    raise ArmModelError(path, f"{where}: <mimic> without joint=\"...\"")
                multiplier = _number(node, "multiplier", where, path)
                offset = _number(node, "offset", where, path)
                mimic = (str(node.get("joint")), 1.0 if multiplier is None else multiplier,
                         0.0 if offset is None else offset)
            origin.flags.writeable = axis.flags.writeable = False  # shared by later reads
            out.append(Joint(name, str(kind), ends["parent"], ends["child"], origin, axis, lower,
                             upper, element.sourceline, mimic))
        return out

    def check_depth(self, note: str = "") -> None:
        """Raise unless every chain from a root link holds at most :data:`MAX_CHAIN_JOINTS` joints.

        Args:
            note: what the tree holds besides the file's joints, for the message.

        Raises:
            ArmModelError: naming the file, the chain's ends and its length.
        """
        children: dict[str, list[str]] = {}
        has_parent = set()
        for element in self.root.iterfind("joint"):
            parent, child = element.find("parent"), element.find("child")
            if parent is not None and child is not None:
                children.setdefault(str(parent.get("link")), []).append(str(child.get("link")))
                has_parent.add(str(child.get("link")))
        roots = [link for link in children if link not in has_parent]
        depth = {link: 0 for link in roots}
        stack = list(roots)
        while stack:  # no recursion: the chain may be deep; a cycle is visited once
            link = stack.pop()
            for child in children.get(link, []):
                if child not in depth:
                    depth[child] = depth[link] + 1
                    stack.append(child)
        deepest = max(depth, key=depth.__getitem__, default=None)
        if deepest is not None and depth[deepest] > MAX_CHAIN_JOINTS:
            raise ArmModelError(self.path, f"a chain of {depth[deepest]:,} joints{note} ends at "
                                           f"link '{deepest}'; at most {MAX_CHAIN_JOINTS:,} on "
                                           "one chain are read (Pinocchio's URDF parser recurses "
                                           "once per joint)")

    # ------------------------------------------------------------------ editing
    def _joint(self, name: str) -> etree._Element:
        if "'" not in name:  # lxml's own search (a name with a quote: the loop below)
            found = self.root.find(f"joint[@name='{name}']")
            if found is not None:
                return found
        for element in self.root.findall("joint"):
            if element.get("name") == name:
                return element
        raise KeyError(name)

    def _child(self, joint: etree._Element, tag: str) -> etree._Element:
        node = joint.find(tag)
        return etree.SubElement(joint, tag) if node is None else node

    def set_origin(self, name: str, origin: np.ndarray, *, keep_rotation: bool = False) -> None:
        """Set a joint's origin (4x4, m).

        ``keep_rotation`` sets only its translation, the rotation's text (``rpy``) kept as written.
        """
        node = self._child(self._joint(name), "origin")
        node.set("xyz", number_text(origin[:3, 3]))
        if not keep_rotation:
            node.set("rpy", number_text(pin.rpy.matrixToRpy(np.asarray(origin[:3, :3], float))))

    def make_fixed(self, name: str) -> None:
        """Turn a joint into a fixed joint at zero (its origin kept)."""
        joint = self._joint(name)
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "mimic", "dynamics", "safety_controller", "calibration"):
            for node in joint.findall(tag):
                joint.remove(node)

    def make_one_dof(self, name: str, kind: str, axis: np.ndarray, zero_origin: bool) -> None:
        """Turn a joint into a ``revolute`` or ``prismatic`` joint along ``axis`` (unit, (3,)).

        Its limits are wide (identification models: every value reachable); ``zero_origin``
        replaces its origin by the identity.
        """
        joint = self._joint(name)
        joint.set("type", kind)
        for node in joint.findall("mimic"):
            joint.remove(node)
        self._child(joint, "axis").set("xyz", number_text(axis))
        limit = self._child(joint, "limit")
        for key, value in (("lower", "-1000"), ("upper", "1000"), ("effort", "0"),
                           ("velocity", "1")):
            limit.set(key, value)
        if zero_origin:
            self.set_origin(name, np.eye(4))

    def remove_joint(self, name: str) -> None:
        """Remove a joint (its child link stays)."""
        self.root.remove(self._joint(name))

    def add_link(self, name: str) -> None:
        """Add an empty link."""
        etree.SubElement(self.root, "link", name=name)

    def insert_fixed(self, name: str, parent: str, child: str, before: str | None = None) -> None:
        """Add a fixed joint at the identity and its empty child link.

        Both are written just before the joint ``before`` (at the end without one), so that the
        text reads in chain order.
        """
        link = etree.Element("link", name=child)
        joint = etree.Element("joint", name=name, type="fixed")
        etree.SubElement(joint, "parent", link=parent)
        etree.SubElement(joint, "child", link=child)
        etree.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
        if before is None:
            self.root.append(joint)
            self.root.append(link)
        else:
            anchor = self._joint(before)
            anchor.addprevious(joint)
            anchor.addprevious(link)
            for node in (joint, link):  # each on its own line
                node.tail = "\n  "

    def set_parent(self, name: str, link: str) -> None:
        """Set a joint's parent link."""
        self._child(self._joint(name), "parent").set("link", link)

    def add_joint(self, name: str, kind: str, parent: str, child: str, axis: np.ndarray) -> None:
        """Add a 1-DOF joint (``revolute`` or ``prismatic``) at the identity along ``axis``."""
        joint = etree.SubElement(self.root, "joint", name=name, type=kind)
        etree.SubElement(joint, "parent", link=parent)
        etree.SubElement(joint, "child", link=child)
        self.make_one_dof(name, kind, axis, zero_origin=True)

    def add_comment(self, text: str) -> None:
        """Add an XML comment at the top of the document, before every other node.

        Raises:
            ValueError: if ``text`` holds ``--`` (XML comments cannot).
        """
        if "--" in text or text.endswith("-"):
            raise ValueError(f"text: an XML comment cannot hold '--' or end with '-': {text!r}")
        nodes = list(self.root.itersiblings(preceding=True))
        (nodes[-1] if nodes else self.root).addprevious(etree.Comment(f" {text} "))

    def xml(self) -> str:
        """Return the URDF text (the document's comments and every element kept)."""
        root = self.root
        nodes = [*reversed(list(root.itersiblings(preceding=True))), root, *root.itersiblings()]
        return "<?xml version='1.0' encoding='UTF-8'?>\n" + "".join(
            etree.tostring(node, encoding="unicode", with_tail=False) + "\n" for node in nodes)


def read_urdf(path: str | Path) -> UrdfTree:
    """Parse a URDF file strictly; return its tree.

    Raises:
        ArmModelError: for a file that cannot be read, broken XML (naming line and column), an
            XML entity declaration (entities are not expanded: an entity could move a link
            unseen; naming its line and column) or a root that is not ``<robot>``.
    """
    _refuse_entities(path)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             huge_tree=False)
    try:
        tree = etree.parse(str(path), parser)
    except etree.XMLSyntaxError as exc:
        line, column = exc.position
        raise ArmModelError(path, f"line {line}, column {column}: invalid XML: {exc.msg}") from None
    except OSError as exc:
        raise ArmModelError(path, f"cannot read the file: {exc}") from None
    out = UrdfTree(tree, path)
    out.check_depth()
    return out


def _refuse_entities(path: str | Path) -> None:
    """Raise if the URDF declares an XML entity.

    Raises:
        ArmModelError: naming the entity, its line and column.
    """
    from xml.parsers import expat

    parser = expat.ParserCreate()

    def declared(name: str, *_: object) -> None:
        raise ArmModelError(path, f"line {parser.CurrentLineNumber}, column "
                                  f"{parser.CurrentColumnNumber + 1}: the XML entity '{name}' is "
                                  "declared; entities are not expanded: write the values out")

    parser.EntityDeclHandler = declared
    try:
        with open(path, "rb") as f:
            parser.ParseFile(f)
    except expat.ExpatError:
        pass  # broken XML: lxml names it next, with its line and column
    except OSError as exc:
        raise ArmModelError(path, f"cannot read the file: {exc}") from None

