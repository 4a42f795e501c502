"""Where an arm's files are: its URDF and its sizes file, by path or by an embedded arm's name.

:func:`resolve_arm_path` finds a URDF, :func:`resolve_sizes_path` a sizes file (an embedded arm's
name gives that arm's). Imports neither Pinocchio nor numpy: the command line checks ``--arm``
and ``--sizes`` with it before the heavy imports (a wrong path is reported at once).
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



def _embedded_sizes(name: str) -> Path:
    """The sizes file beside an embedded arm's URDF (which may not exist: the defaults)."""
    urdf = resolve_arm_path(name)
    return urdf.with_name(urdf.name.removesuffix(".urdf") + ".sizes.json")


def resolve_sizes_path(sizes: str | Path) -> Path:
    """Return the sizes file given by path or by the name of an embedded arm (that arm's file).

    ``--sizes ur5`` gives the embedded UR5's sizes to another URDF of the same robot (one without
    a sizes file beside it), reachable from any folder once the package is installed.

    Raises:
        ArmModelError: if it is neither an existing file nor an embedded arm with a sizes file.
    """
    path = Path(sizes)
    if path.is_file():
        return path
    name = str(sizes)
    with_sizes = [arm for arm in EMBEDDED if _embedded_sizes(arm).is_file()]
    if name in with_sizes:
        return _embedded_sizes(name)
    raise ArmModelError(sizes, f"no such sizes file, and no embedded arm with sizes named '{name}' "
                               f"(embedded arms with sizes: {', '.join(with_sizes)})")
