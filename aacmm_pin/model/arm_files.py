"""Where an arm's URDF is: :func:`resolve_arm_path` (a path, or an embedded arm's name).

Imports neither Pinocchio nor numpy: the command line checks ``--arm`` with it before the heavy
imports (a wrong path is reported at once).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from aacmm_pin.errors import ArmModelError

EMBEDDED = ("aacmm7", "ur5", "wam7", "torso", "torso_coupled")
"""Arms shipped with the package (``pyproject.toml``'s wheel ``force-include``, each URDF with its
sizes file), loadable by name: the default AACMM, the two robots of the public laser-tracker data
(``urdf/make_serial_dh.py`` writes them from the makers' DH tables), and the two-armed torsos of
the docs, one with a coupled joint (``urdf/make_torso.py``, ``urdf/make_torso_coupled.py``)."""


def resolve_arm_path(arm: str | Path) -> Path:
    """Return the URDF path of an arm given by path or by the name of an embedded arm.

    Raises:
        ArmModelError: if it is neither an existing file nor an embedded arm's name.
    """
    path = Path(arm)
    if path.is_file():
        return path
    name = str(arm)
    candidates = [resources.files("aacmm_pin") / "urdf" / f"{name}.urdf",
                  Path(__file__).resolve().parents[2] / "urdf" / f"{name}.urdf"]
    for candidate in candidates:
        if candidate.is_file():
            return Path(str(candidate))
    raise ArmModelError(arm, f"no such URDF file, and no embedded arm named '{name}' "
                             f"(embedded: {', '.join(EMBEDDED)})")
