"""The command's garbage collector: off while a module loads, what the load made frozen after."""

from __future__ import annotations

import builtins
import gc
import sys

import pytest

from aacmm_pin.cli._collector import imports_uncollected


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
    module's 5000 lists frozen (never traversed); ``__import__`` is restored on exit."""
    original = builtins.__import__
    frozen = gc.get_freeze_count()
    try:
        with imports_uncollected():
            assert builtins.__import__ is not original
            import collector_probe  # noqa: F401  (through the hook: a statement, not importlib)

            assert gc.isenabled()
            assert gc.get_freeze_count() >= frozen + 5000
        assert sys.modules["collector_probe"].ENABLED is False
        assert builtins.__import__ is original
    finally:
        gc.unfreeze()  # the test process's objects back to the collector


def test_a_loaded_module_or_an_off_collector_changes_nothing(module_file):
    """Importing what is loaded freezes nothing; with the caller's collector off it stays off."""
    try:
        with imports_uncollected():
            import collector_probe  # noqa: F401
            frozen = gc.get_freeze_count()
            import collector_probe  # noqa: F401, F811  (loaded: no freeze)

            assert gc.get_freeze_count() == frozen
            gc.disable()
            try:
                import json  # noqa: F401
                assert not gc.isenabled()
            finally:
                gc.enable()
    finally:
        gc.unfreeze()


def test_an_import_that_fails_turns_the_collector_on_again():
    """A module that raises while it loads leaves the collector on and the error raised."""
    with imports_uncollected(), pytest.raises(ModuleNotFoundError):
        import collector_probe_absent  # noqa: F401
    assert gc.isenabled()
