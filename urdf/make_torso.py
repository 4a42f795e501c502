r"""Write ``torso.urdf``: a torso with two 7-axis arms and a marker on each hand (a kinematic tree).

Run once; the URDF is committed: ``python urdf/make_torso.py`` writes ``torso.urdf`` and its sizes
file ``torso.sizes.json`` (:data:`SIZES`) next to this script. It is a made-up robot (no maker's data) for tests and examples of arms with several tools:

* ``T1``: torso yaw, a revolute about z on ``base_link``; the torso carries both shoulders.
* ``L1..L7`` (left, shoulder at y = +0.25 m) and ``R1..R7`` (right, y = -0.25 m): seven revolutes
  each, alternately about z (roll along the arm) and y (pitch), the arm pointing sideways out of
  the torso; upper arm 0.30 m, forearm 0.28 m, hand 0.08 m.
* ``tool_left`` / ``tool_right``: fixed joints carrying each hand's marker (the tools ``left`` and
  ``right``), 0.1 m beyond the last axis and 0.03 m off it.

Error frames, all zero (aacmm_pin's conventions, :mod:`aacmm_pin.model.arm`), named with the axis'
position k in the tree (torso 1, left 2..8, right 9..15): ``dth<k>`` before every axis (the axis
offset), and after it, but for the hands' last axes (the tool vector holds that), two translations
and one rotation perpendicular to the axis (``dx<k>``, ``dy<k>``, ``a<k>`` after a z axis;
``dx<k>``, ``dz<k>``, ``c<k>`` after a y axis).

Mass properties: solid cylinders of each link's length (masses below), so that gravity loads the
pitch axes (a joint compliance model needs them).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

LENGTHS = (0.05, 0.0, 0.30, 0.0, 0.28, 0.0, 0.08)
"""Offset along the arm (local z) from the previous axis to axis 1..7, m."""
MASSES = (2.0, 2.0, 1.6, 1.4, 1.1, 0.8, 0.4)
"""Mass of the link each axis moves, kg."""
AXES = "zyzyzyz"
"""Axis direction of joints 1..7 in the arm's frame (z along the arm)."""
TOOL = (0.03, 0.0, 0.10)
"""Marker in the last link's frame, m."""
LIMITS_DEG = {"z": 170.0, "y": 115.0}
"""Symmetric joint limits per axis direction, deg."""
SIDES = (("left", "L", 1.0, 2), ("right", "R", -1.0, 9))
"""(tool name, axis prefix, sign of y, tree position of the first axis)."""


def _f(v: float) -> str:
    return f"{v:.12g}" if abs(v) > 1e-15 else "0"


def _joint(name: str, kind: str, parent: str, child: str, xyz=(0, 0, 0), rpy=(0, 0, 0),
           axis: str | None = None, limit_deg: float | None = None) -> str:
    out = [f'  <joint name="{name}" type="{kind}">\n',
           f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n',
           f'    <origin xyz="{" ".join(map(_f, xyz))}" rpy="{" ".join(map(_f, rpy))}"/>\n']
    if axis is not None:
        lim = math.radians(LIMITS_DEG[axis] if limit_deg is None else limit_deg)
        vec = {"z": "0 0 1", "y": "0 1 0"}[axis]
        out.append(f'    <axis xyz="{vec}"/>\n'
                   f'    <limit lower="{_f(-lim)}" upper="{_f(lim)}" effort="100" velocity="2"/>\n')
    out.append("  </joint>\n")
    return "".join(out)


def _link(name: str, mass: float = 0.0, length: float = 0.0, radius: float = 0.04) -> str:
    if mass == 0.0:
        return f'  <link name="{name}"/>\n'
    i_perp = mass * (3 * radius ** 2 + length ** 2) / 12
    i_axis = 0.5 * mass * radius ** 2
    return (f'  <link name="{name}">\n    <inertial>\n'
            f'      <origin xyz="0 0 {_f(length / 2)}" rpy="0 0 0"/>\n'
            f'      <mass value="{_f(mass)}"/>\n'
            f'      <inertia ixx="{_f(i_perp)}" ixy="0" ixz="0" iyy="{_f(i_perp)}" iyz="0" '
            f'izz="{_f(i_axis)}"/>\n    </inertial>\n  </link>\n')


def _errors_after(k: int, axis: str, parent: str) -> tuple[list[str], str]:
    """Return the error frames after axis k (about ``axis``) and the last link's name."""
    names = (f"dx{k}", f"dy{k}", f"a{k}") if axis == "z" else (f"dx{k}", f"dz{k}", f"c{k}")
    parts = []
    for name in names:
        parts += [_joint(name, "fixed", parent, f"{name}_frame"), _link(f"{name}_frame")]
        parent = f"{name}_frame"
    return parts, parent


def _arms(torso_end: str, sides: tuple[tuple[str, str, float, int], ...] = SIDES,
          height: float = 0.6) -> list[str]:
    """Return the two arms' joints and links, mounted on link ``torso_end`` at ``height`` m."""
    parts = []
    for tool, prefix, sign, first in sides:
        mount = f"{tool}_shoulder"
        parts += [_joint(mount, "fixed", torso_end, f"{mount}_frame", (0, sign * 0.25, height),
                         (-sign * math.pi / 2, 0, 0)), _link(f"{mount}_frame")]
        parent = f"{mount}_frame"
        for i, (length, mass, axis) in enumerate(zip(LENGTHS, MASSES, AXES)):
            k = first + i
            nxt = LENGTHS[i + 1] if i + 1 < len(LENGTHS) else TOOL[2]
            parts += [_joint(f"dth{k}", "fixed", parent, f"dth{k}_frame"),
                      _link(f"dth{k}_frame"),
                      _joint(f"{prefix}{i + 1}", "revolute", f"dth{k}_frame",
                             f"{prefix.lower()}{i + 1}", (0, 0, length), axis=axis),
                      _link(f"{prefix.lower()}{i + 1}", mass, max(nxt, 0.05), 0.04)]
            parent = f"{prefix.lower()}{i + 1}"
            if i + 1 < len(LENGTHS):  # after the last axis the tool vector says it all
                errors, parent = _errors_after(k, axis, parent)
                parts += errors
        parts += [_joint(f"tool_{tool}", "fixed", parent, f"marker_{tool}", TOOL),
                  _link(f"marker_{tool}")]
    return parts


def make_urdf() -> str:
    """Return the URDF text of the torso with two arms."""
    parts = ['<?xml version="1.0"?>\n',
             "<!-- torso: a made-up torso with two 7-axis arms, written by urdf/make_torso.py "
             "(15 axes, 54 error frames at 0, tools left and right). -->\n",
             '<robot name="torso">\n', _link("base_link", 20.0, 0.1, 0.2),
             _joint("dth1", "fixed", "base_link", "dth1_frame"), _link("dth1_frame"),
             _joint("T1", "revolute", "dth1_frame", "torso", (0, 0, 0.1), axis="z"),
             _link("torso", 15.0, 0.6, 0.15)]
    errors, torso_end = _errors_after(1, "z", "torso")
    parts += errors + _arms(torso_end)
    parts.append("</robot>\n")
    return "".join(parts)


SIZES = {
    "units": "SI",
    "source": ("Physics, not fitted to any data; the default AACMM's sizes but for one. Lateral "
               "compliance: a humanoid's joints carry their links on compact cross-roller "
               "bearings and thin-walled links whose tilting stiffness is of order 3e4 N m/rad, "
               "so 3e-5 rad/(N m) about each lateral axis (about 0.07 deg under the torso's "
               "40 N m of lateral gravity moment; 3x the default, as a UR5's axial compliance)."),
    "effects": {"lateral_compliance": 3e-5},
}
"""The torso's plausible sizes (``torso.sizes.json``, :mod:`aacmm_pin.model.sizes`)."""


def make_sizes() -> str:
    """Return the text of ``torso.sizes.json``."""
    return json.dumps(SIZES, indent=2) + "\n"


def main() -> None:
    """Write ``torso.urdf`` and ``torso.sizes.json`` next to this script."""
    for name, text in (("torso.urdf", make_urdf()), ("torso.sizes.json", make_sizes())):
        out = Path(__file__).with_name(name)
        out.write_text(text)
        print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
