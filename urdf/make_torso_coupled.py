r"""Write ``torso_coupled.urdf``: a torso with a passive coupled joint and two 7-axis arms.

Run once; the URDF is committed: ``python urdf/make_torso_coupled.py`` writes
``torso_coupled.urdf`` and its sidecar ``torso_coupled.sizes.json`` (:data:`SIZES`, which states
the coupling) next to this script. A made-up humanoid torso (no maker's data) for tests and
examples of coupled joints (:mod:`aacmm_pin.data.couplings`):

* ``T1``: waist yaw about z; ``T2``, ``T3``: two pitch joints about y (hip and waist, +-30 deg);
  ``T4``: a passive pitch joint about y that a linkage holds at :math:`q_4 = -(q_2 + q_3)`, so that
  the chest stays level (no encoder; the ``couplings`` block of the sizes file says so, which a
  URDF ``<mimic>`` cannot: it follows one joint).
* ``L1..L7`` and ``R1..R7``: the arms of ``urdf/make_torso.py`` on the chest, the marker tools
  ``left`` and ``right``.

Error frames as in ``make_torso.py``, named with the axis' position k in the tree (torso 1..4,
left 5..11, right 12..18): ``dth<k>`` before every axis and two translations and a rotation after
it (the coupled joint's too: its link exists).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from make_torso import _arms, _errors_after, _joint, _link

TORSO = (("T1", "z", 0.10, 8.0, 0.15, None), ("T2", "y", 0.15, 8.0, 0.25, 30.0),
         ("T3", "y", 0.25, 6.0, 0.25, 30.0), ("T4", "y", 0.25, 15.0, 0.45, 60.0))
"""Torso axes: (name, axis, height above the previous axis m, mass of the link it moves kg, that
link's length m, symmetric limit deg or None for make_torso's)."""
SIDES = (("left", "L", 1.0, 5), ("right", "R", -1.0, 12))
"""(tool name, axis prefix, sign of y, tree position of the first axis)."""
SHOULDER_HEIGHT = 0.35
"""Shoulders above the coupled joint T4, m."""
SIZES = {
    "units": "SI",
    "source": ("Physics, not fitted to any data: the default AACMM's sizes. The coupling is the "
               "chest linkage's: the passive T4 keeps the chest level, q4 = -(q2 + q3)."),
    "couplings": {"T4": {"of": {"T2": -1.0, "T3": -1.0}, "offset": 0.0}},
}
"""The torso's sidecar (``torso_coupled.sizes.json``): default sizes and the coupling of T4."""


def make_urdf() -> str:
    """Return the URDF text of the coupled torso with two arms."""
    parts = ['<?xml version="1.0"?>\n',
             "<!-- torso_coupled: a made-up torso with a coupled joint T4 = -(T2 + T3) and two "
             "7-axis arms, written by urdf/make_torso_coupled.py (18 axes, tools left and "
             "right). -->\n",
             '<robot name="torso_coupled">\n', _link("base_link", 20.0, 0.1, 0.2)]
    parent = "base_link"
    for k, (name, axis, height, mass, length, limit) in enumerate(TORSO, 1):
        link = f"torso{k}"
        parts += [_joint(f"dth{k}", "fixed", parent, f"dth{k}_frame"), _link(f"dth{k}_frame"),
                  _joint(name, "revolute", f"dth{k}_frame", link, (0, 0, height), axis=axis,
                         limit_deg=limit),
                  _link(link, mass, length, 0.15)]
        errors, parent = _errors_after(k, axis, link)
        parts += errors
    parts += _arms(parent, SIDES, SHOULDER_HEIGHT)
    parts.append("</robot>\n")
    return "".join(parts)


def main() -> None:
    """Write ``torso_coupled.urdf`` and ``torso_coupled.sizes.json`` next to this script."""
    for name, text in (("torso_coupled.urdf", make_urdf()),
                       ("torso_coupled.sizes.json", json.dumps(SIZES, indent=2) + "\n")):
        out = Path(__file__).with_name(name)
        out.write_text(text)
        print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
