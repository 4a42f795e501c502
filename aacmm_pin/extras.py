"""The optional parts of aacmm_pin (the package's extras) and the one line that names a missing one.

``pip install aacmm_pin`` is the runtime: load an arm and a calibration, predict, identify, validate,
discover, plan (Pinocchio, numpy, scipy, lxml, tqdm, threadpoolctl). The rest is in extras
(``pyproject.toml``), each imported only inside the function that needs it:

* ``figures``: matplotlib, the PNG figures (``demo``, ``discover``, ``uncertainty``, the plots);
* ``viewer``: meshcat (and matplotlib for its legend), ``aacmm-pin view``;
* ``serial``: pyserial, ``aacmm-pin acquire``;
* ``urdf``: yourdfpy, :meth:`aacmm_pin.Arm.urdf_robot`;
* ``all``: every one of them (``pip install "aacmm_pin[all]"``).

:func:`require` imports an extra's modules or raises
:class:`~aacmm_pin.errors.MissingExtraError` naming what needs it and the install command;
:func:`skipped` is for the commands that write their results without figures when matplotlib is
missing.
"""

from __future__ import annotations

import importlib
import sys

from aacmm_pin.errors import MissingExtraError

EXTRAS: dict[str, tuple[str, ...]] = {
    "figures": ("matplotlib",),
    "viewer": ("meshcat", "matplotlib"),
    "serial": ("serial",),
    "urdf": ("yourdfpy",),
}
"""Extra -> the top-level modules it installs that the package imports (pyproject's extras)."""
DISTRIBUTIONS = {"serial": "pyserial"}
"""Module -> the name it is installed by, where they differ (for the messages)."""


def require(extra: str, needed_by: str) -> None:
    """Import the modules of ``extra`` (once), or raise naming ``needed_by`` and the install command.

    Args:
        extra: a key of :data:`EXTRAS`.
        needed_by: what needs it, as the user called it: ``view``, ``Arm.urdf_robot``, ``figures``.

    Raises:
        MissingExtraError: if one of its modules (or a module one of them imports) is not installed.
    """
    for module in EXTRAS[extra]:
        if module in sys.modules:
            continue
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            missing = exc.name or module
            raise MissingExtraError(needed_by, extra, missing, DISTRIBUTIONS.get(missing)) from None


def skipped(extra: str, what: str) -> str | None:
    """Return None if ``extra`` is installed, else one line saying that ``what`` was skipped and why.

    E.g. ``figures skipped: the figures extra (matplotlib) is not installed: pip install
    "aacmm_pin[figures]"``, for a command that writes its results and leaves out what needs the
    extra.
    """
    try:
        require(extra, what)
    except MissingExtraError as exc:
        return (f"{what} skipped: the {extra} extra ({exc.package}) is not installed: "
                f'pip install "aacmm_pin[{extra}]"')
    return None
