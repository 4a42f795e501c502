"""Write ``aacmm7.urdf``, the default seven-axis arm of aacmm_pin (run once; the URDF is committed).

The chain is the paper's Eq. (2) (Ibaraki & Saito, CIRP Annals 2023), one elementary transform per
joint, applied left to right:

    rT1 = Dc(th1)
    1T2 = Dx(dx21) Dz(L2z) Da(a21) Db(th2)
    2T3 = Dx(L3x) Dy(dy32) Dz(L3z + dz32) Db(b32) Dc(c32) Da(th3 + dth30)
    3T4 = Dx(dx43) Dz(dz43) Dc(c43) Db(th4 + dth40)
    4T5 = Dx(L5x + dx54) Dy(dy54) Dz(-L5z) Da(a54) Dc(th5 + dth50)
    5T6 = Dx(dx65) Dz(dz65) Da(a65) Db(th6 + dth60)
    6T7 = Dx(L7x + dx76) Dy(dy76) Da(a76) Dc(th7)
    7p  = tool vector

Nominal lengths are fixed joints named after them, the 22 DH error parameters are fixed joints
(error frames) named exactly as in the paper, all at zero here, and the tool vector is the fixed
joint ``tool``. Usage: ``python urdf/make_aacmm7.py`` (writes next to this script).
"""

from __future__ import annotations

import math
from pathlib import Path

# link name, mass (kg), visual cylinders: (length m, radius m, xyz of centre, rpy)
HALF_PI = math.pi / 2
LINKS = {
    "base_link": (1.2, [(0.20, 0.045, (0, 0, 0.10), (0, 0, 0))]),
    "link1": (0.45, [(0.08, 0.040, (0, 0, 0.16), (0, 0, 0))]),
    "link2": (0.55, [(0.60, 0.022, (0.30, 0, 0.0), (0, HALF_PI, 0)),
                     (0.05, 0.030, (0.60, 0, 0.025), (0, 0, 0))]),
    "link3": (0.25, [(0.08, 0.032, (0, 0, 0), (0, HALF_PI, 0))]),
    "link4": (0.45, [(0.55, 0.020, (0.05, 0, -0.275), (0, 0, 0)),
                     (0.05, 0.025, (0.025, 0, 0), (0, HALF_PI, 0))]),
    "link5": (0.20, [(0.06, 0.028, (0, 0, 0), (0, 0, 0))]),
    "link6": (0.15, [(0.10, 0.018, (0.05, 0, 0), (0, HALF_PI, 0))]),
    "link7": (0.12, [(0.12, 0.010, (0, 0, -0.06), (0, 0, 0))]),
}
# (parent link, name, type, xyz, rpy, axis, limit deg, child link)
AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def chain() -> list[tuple[str, str, str, tuple, str | None, float | None]]:
    """Return the joints as (name, kind, elementary transform, value, axis, limit_deg)."""
    return [
        ("A1", "revolute", "c", 0.0, "z", 180),
        ("L2z", "fixed", "z", 0.200, None, None),
        ("dx21", "fixed", "x", 0.0, None, None),
        ("a21", "fixed", "a", 0.0, None, None),
        ("A2", "revolute", "b", 0.0, "y", 100),
        ("L3x", "fixed", "x", 0.600, None, None),
        ("L3z", "fixed", "z", 0.050, None, None),
        ("dy32", "fixed", "y", 0.0, None, None),
        ("dz32", "fixed", "z", 0.0, None, None),
        ("b32", "fixed", "b", 0.0, None, None),
        ("c32", "fixed", "c", 0.0, None, None),
        ("dth30", "fixed", "a", 0.0, None, None),
        ("A3", "revolute", "a", 0.0, "x", 180),
        ("dx43", "fixed", "x", 0.0, None, None),
        ("dz43", "fixed", "z", 0.0, None, None),
        ("c43", "fixed", "c", 0.0, None, None),
        ("dth40", "fixed", "b", 0.0, None, None),
        ("A4", "revolute", "b", 0.0, "y", 150),
        ("L5x", "fixed", "x", 0.050, None, None),
        ("dx54", "fixed", "x", 0.0, None, None),
        ("dy54", "fixed", "y", 0.0, None, None),
        ("L5z", "fixed", "z", -0.550, None, None),
        ("a54", "fixed", "a", 0.0, None, None),
        ("dth50", "fixed", "c", 0.0, None, None),
        ("A5", "revolute", "c", 0.0, "z", 180),
        ("dx65", "fixed", "x", 0.0, None, None),
        ("dz65", "fixed", "z", 0.0, None, None),
        ("a65", "fixed", "a", 0.0, None, None),
        ("dth60", "fixed", "b", 0.0, None, None),
        ("A6", "revolute", "b", 0.0, "y", 120),
        ("L7x", "fixed", "x", 0.100, None, None),
        ("dx76", "fixed", "x", 0.0, None, None),
        ("dy76", "fixed", "y", 0.0, None, None),
        ("a76", "fixed", "a", 0.0, None, None),
        ("A7", "revolute", "c", 0.0, "z", 180),
    ]


def _fmt(v: float) -> str:
    return f"{v:.12g}"


def _cyl_inertia(m: float, length: float, r: float, rpy: tuple) -> tuple[float, float, float]:
    """Diagonal inertia of a solid cylinder, axis along z, or along x when pitched by 90 deg."""
    i_axis = 0.5 * m * r * r
    i_perp = m * (3 * r * r + length * length) / 12
    if abs(rpy[1]) > 1e-9:  # cylinder along x
        return i_axis, i_perp, i_perp
    return i_perp, i_perp, i_axis


def _link(name: str) -> str:
    if name not in LINKS:
        return f'  <link name="{name}"/>\n'
    mass, cyls = LINKS[name]
    length, r, xyz, rpy = cyls[0]
    ixx, iyy, izz = _cyl_inertia(mass, length, r, rpy)
    out = [f'  <link name="{name}">\n',
           "    <inertial>\n",
           f'      <origin xyz="{" ".join(_fmt(v) for v in xyz)}" rpy="0 0 0"/>\n',
           f'      <mass value="{_fmt(mass)}"/>\n',
           f'      <inertia ixx="{_fmt(ixx)}" ixy="0" ixz="0" iyy="{_fmt(iyy)}" iyz="0" '
           f'izz="{_fmt(izz)}"/>\n',
           "    </inertial>\n"]
    for length, r, xyz, rpy in cyls:
        out += ["    <visual>\n",
                f'      <origin xyz="{" ".join(_fmt(v) for v in xyz)}" '
                f'rpy="{" ".join(_fmt(v) for v in rpy)}"/>\n',
                f'      <geometry><cylinder length="{_fmt(length)}" radius="{_fmt(r)}"/>'
                "</geometry>\n",
                '      <material name="carbon"/>\n',
                "    </visual>\n"]
    out.append("  </link>\n")
    return "".join(out)


def make_urdf() -> str:
    """Return the URDF text of the default arm."""
    parts = ['<?xml version="1.0"?>\n',
             "<!-- aacmm7: default 7-axis AACMM of aacmm_pin, paper Eq. (2); see make_aacmm7.py -->\n",
             '<robot name="aacmm7">\n',
             '  <material name="carbon"><color rgba="0.15 0.15 0.17 1"/></material>\n',
             '  <material name="steel"><color rgba="0.75 0.75 0.8 1"/></material>\n',
             _link("base_link")]
    parent = "base_link"
    n_axis = 0
    for name, kind, elem, value, axis, limit in chain():
        if kind == "revolute":
            n_axis += 1
            child = f"link{n_axis}"
        else:
            child = f"{name}_frame"
        xyz = [0.0, 0.0, 0.0]
        rpy = [0.0, 0.0, 0.0]
        if elem in "xyz":
            xyz["xyz".index(elem)] = value
        else:
            rpy["abc".index(elem)] = value
        parts.append(f'  <joint name="{name}" type="{kind}">\n'
                     f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
                     f'    <origin xyz="{" ".join(_fmt(v) for v in xyz)}" '
                     f'rpy="{" ".join(_fmt(v) for v in rpy)}"/>\n')
        if kind == "revolute":
            lim = math.radians(limit)
            parts.append(f'    <axis xyz="{" ".join(str(v) for v in AXES[axis])}"/>\n'
                         f'    <limit lower="{_fmt(-lim)}" upper="{_fmt(lim)}" effort="0" '
                         'velocity="3.14"/>\n')
        parts.append("  </joint>\n")
        parts.append(_link(child))
        parent = child
    parts.append('  <joint name="tool" type="fixed">\n'
                 f'    <parent link="{parent}"/>\n    <child link="stylus"/>\n'
                 '    <origin xyz="0 0 -0.12" rpy="0 0 0"/>\n  </joint>\n'
                 '  <link name="stylus">\n    <visual>\n      <origin xyz="0 0 0" rpy="0 0 0"/>\n'
                 '      <geometry><sphere radius="0.003"/></geometry>\n'
                 '      <material name="steel"/>\n    </visual>\n  </link>\n')
    parts.append("</robot>\n")
    return "".join(parts)


if __name__ == "__main__":
    out = Path(__file__).with_name("aacmm7.urdf")
    out.write_text(make_urdf())
    print(f"wrote {out}")
