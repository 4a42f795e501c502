"""The embedded arms ship with the package, and the documented commands name arms a user has."""

from __future__ import annotations

import re

import aacmm_pin as ap
from aacmm_pin.model.arm_files import EMBEDDED
from tests.helpers import ROOT
from tests.test_docs import ALL, shell_lines

ARM = re.compile(r"(?:--arm|aacmm-pin axes)\s+(\S+)")


def test_every_embedded_arm_is_force_included_in_the_wheel() -> None:
    """Each embedded arm's URDF and sizes file are copied into aacmm_pin/urdf/ of the wheel
    (torso_coupled was not: an installed package had no embedded arm of that name)."""
    text = (ROOT / "pyproject.toml").read_text()
    for name in EMBEDDED:
        assert f'"urdf/{name}.urdf" = "aacmm_pin/urdf/{name}.urdf"' in text, name
        if (ROOT / "urdf" / f"{name}.sizes.json").is_file():
            assert f'"urdf/{name}.sizes.json" = "aacmm_pin/urdf/{name}.sizes.json"' in text, name
        assert ap.load_arm(name).n_axes > 0


def test_documented_commands_name_arms_an_installed_package_has() -> None:
    """A command in a runnable block of the README or docs names an embedded arm or a file it
    can reach from a fresh folder, never the repository's urdf/ folder."""
    bad = []
    for block in ALL:
        if block.lang != "bash" or not block.runs:
            continue
        for line in shell_lines(block.text):
            bad += [f"{block.id}: {arm}" for arm in ARM.findall(line)
                    if arm.startswith("urdf/") or ("/" not in arm and not arm.endswith(".urdf")
                                                   and arm not in EMBEDDED)]
    assert not bad, bad
