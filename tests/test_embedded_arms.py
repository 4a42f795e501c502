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


def test_sizes_names_an_embedded_arm(tmp_path, capsys) -> None:
    """``--sizes ur5`` (``load_arm(..., sizes="ur5")``) gives another URDF the embedded UR5's sizes
    from any folder; a name that is neither a file nor an embedded arm with sizes is refused in one
    line naming it (exit status 2), before any work."""
    from aacmm_pin.cli import main
    from aacmm_pin.model.arm_files import resolve_sizes_path

    urdf = tmp_path / "my_ur5.urdf"  # the UR5 under another name: no sizes file beside it
    urdf.write_text((ROOT / "urdf" / "ur5.urdf").read_text())
    assert ap.load_arm(urdf).sizes != ap.load_arm("ur5").sizes
    assert ap.load_arm(urdf, sizes="ur5").sizes == ap.load_arm("ur5").sizes
    assert resolve_sizes_path("ur5").name == "ur5.sizes.json"
    assert main(["axes", str(urdf), "--sizes", "ur5"]) == 0
    capsys.readouterr()
    assert main(["axes", str(urdf), "--sizes", "ur6"]) == 2
    err = capsys.readouterr().err
    assert "ur6" in err and "embedded arms with sizes: ur5" in err and len(err.strip().splitlines()) == 1
