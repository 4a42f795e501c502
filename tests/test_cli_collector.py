"""The command's garbage collector: off while a module loads, what the load made frozen after."""

from __future__ import annotations

import builtins
import gc
import subprocess
import sys

import pytest

from aacmm_pin.cli._collector import imports_uncollected
from tests.helpers import ENV


@pytest.fixture
def module_file(tmp_path, monkeypatch):
    """A module ``collector_probe`` that records whether the collector ran while it loaded."""
    (tmp_path / "collector_probe.py").write_text(
        "import gc\nENABLED = gc.isenabled()\nHELD = [[] for _ in range(5000)]\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "collector_probe"
    sys.modules.pop("collector_probe", None)


def test_a_module_loads_without_the_collector_and_its_objects_are_frozen(module_file):
    """The import runs with the collector off; the collector is on again after, with the new
    module's 5000 lists frozen (never traversed); on exit ``__import__`` is restored and the
    frozen objects are returned to the collector (the caller's process goes on)."""
    original = builtins.__import__
    assert gc.get_freeze_count() == 0
    with imports_uncollected():
        assert builtins.__import__ is not original
        import collector_probe  # noqa: F401  (through the hook: a statement, not importlib)

        assert gc.isenabled()
        assert gc.get_freeze_count() >= 5000
    assert sys.modules["collector_probe"].ENABLED is False
    assert builtins.__import__ is original
    assert gc.get_freeze_count() == 0


def test_the_program_keeps_them_frozen_to_its_exit(module_file):
    """``keep_frozen`` (the program, which exits next) leaves the imports' objects frozen."""
    try:
        with imports_uncollected(keep_frozen=True):
            import collector_probe  # noqa: F401
        assert gc.get_freeze_count() >= 5000
    finally:
        gc.unfreeze()


def test_main_in_a_process_that_goes_on_leaves_nothing_frozen():
    """``aacmm_pin.cli.main`` called from Python in a fresh process (its command imports numpy,
    Pinocchio and the package) freezes while it imports and returns every object at its end."""
    code = ("import gc, io, contextlib\n"
            "from aacmm_pin import cli\n"
            "seen, freeze = [], gc.freeze\n"
            "gc.freeze = lambda: (freeze(), seen.append(gc.get_freeze_count()))\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    status = cli.main(['axes', 'ur5'])\n"
            "print(status, max(seen, default=0), gc.get_freeze_count())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV,
                         check=True).stdout.split()
    status, most, after = (int(v) for v in out)
    assert status == 0 and most > 10_000 and after == 0


def test_a_loaded_module_or_an_off_collector_changes_nothing(module_file):
    """Importing what is loaded freezes nothing; with the caller's collector off it stays off."""
    with imports_uncollected():
        import collector_probe  # noqa: F401
        frozen = gc.get_freeze_count()
        import collector_probe  # noqa: F401, F811  (loaded: no freeze)

        assert gc.get_freeze_count() <= frozen  # nothing added (frozen objects may be freed)
        gc.disable()
        try:
            import json  # noqa: F401
            assert not gc.isenabled()
        finally:
            gc.enable()


def test_an_import_that_fails_turns_the_collector_on_again():
    """A module that raises while it loads leaves the collector on and the error raised."""
    with imports_uncollected(), pytest.raises(ModuleNotFoundError):
        import collector_probe_absent  # noqa: F401
    assert gc.isenabled()


def test_overlapping_uses_share_one_hook_and_the_last_restores_import():
    """Commands run by threads overlap: A enters, B enters, A leaves, B leaves; the hook stays
    while either is in force and ``__import__`` is the original after both."""
    original = builtins.__import__
    a, b = imports_uncollected(), imports_uncollected()
    a.__enter__()
    b.__enter__()
    a.__exit__(None, None, None)
    assert builtins.__import__ is not original  # B still in force
    b.__exit__(None, None, None)
    assert builtins.__import__ is original
    assert gc.get_freeze_count() == 0


def test_garbage_waiting_for_a_collection_is_freed_not_frozen(module_file, tmp_path):
    """A cycle dropped before a module loads mid-command is collected, not frozen with the rest."""
    import weakref

    class Node:
        pass

    (tmp_path / "collector_probe_two.py").write_text("X = 1\n")
    try:
        with imports_uncollected():
            import collector_probe  # noqa: F401  (the command has started: objects frozen)

            cycle = Node()
            cycle.self = cycle  # type: ignore[attr-defined]
            alive = weakref.ref(cycle)
            del cycle
            import collector_probe_two  # noqa: F401
            gc.collect()
            assert alive() is None
    finally:
        sys.modules.pop("collector_probe_two", None)
