"""The command's garbage collector: off while a module is imported, its objects set aside after.

A command imports some 10^5 objects that live until it exits (numpy, SciPy, Pinocchio and the
package: modules, classes, functions, docstrings). With the collector on, every 700 new objects
start a collection that traverses the young ones, and the older generations' collections traverse
them again: in a UR5 ``identify`` about 160 collections, ~80 ms of CPU (6 % of the process), that
free ~900 objects. :func:`imports_uncollected` turns the collector off while an ``import``
statement loads modules and freezes what exists when it ends (``gc.freeze``: moved to the
permanent generation, which the collector never traverses; reference counting still frees each
object whose last reference goes). The collector runs as usual between imports, over what the
command's work creates.

What is frozen is what the process holds when a module is first loaded: what the modules made,
and the command's data of that moment. A cycle among frozen objects is not collected while it is
frozen; the modules load at the command's start or at the first use of a part (the solver, the
figures), so that is at most the data of a few moments, once. :func:`aacmm_pin.cli.main` (a
caller's process goes on) returns them to the collector at its end; :func:`aacmm_pin.cli.run`, the
program, keeps them frozen to its exit, whose last collection then skips them (a UR5 ``identify``
ends ~0.1 s sooner than one that collects them).
"""

from __future__ import annotations

import builtins
import contextlib
import gc
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

_LOCK = threading.Lock()


class _Hook:
    """The shared hook's state: nested or concurrent users (commands run by threads) share one."""

    users = 0
    """:func:`imports_uncollected` blocks in force."""
    original: Callable[..., Any] = builtins.__import__
    """``builtins.__import__`` as the first user found it."""
    frozen_before = 0
    """Objects frozen when the first user installed the hook (the caller's own)."""
    keep = False
    """Whether a user asked ``keep_frozen``."""


def _importing(name: str, globals: Any = None, locals: Any = None, fromlist: Any = (),
               level: int = 0) -> Any:
    """``builtins.__import__`` with the collector off while modules load, their objects frozen.

    Before a module that is not loaded yet is imported, where objects are frozen already (the
    command has started), the collector first runs over what is not frozen: garbage waiting for
    a collection is freed, not frozen with the rest (the objects made since the last freeze: few
    at the start, a command's live data later on).
    """
    original = _Hook.original
    if not gc.isenabled():  # an import inside an import, or the caller's own gc.disable()
        return original(name, globals, locals, fromlist, level)
    loaded = len(sys.modules)
    if level == 0 and name not in sys.modules and gc.get_freeze_count():
        gc.collect()
    gc.disable()
    try:
        return original(name, globals, locals, fromlist, level)
    finally:
        if len(sys.modules) != loaded:
            gc.freeze()
        gc.enable()


@contextlib.contextmanager
def imports_uncollected(keep_frozen: bool = False) -> Iterator[None]:
    """Within: ``import`` statements run without the collector; what they load is frozen after.

    Only an import that loads a module freezes (a statement naming loaded modules costs a length
    check); an import inside an import, or one while the collector is off (the caller's own
    ``gc.disable()``), changes nothing. Nested or concurrent uses (commands run by threads) share
    one hook: installed by the first, ``builtins.__import__`` restored by the last. Then the
    frozen objects are returned to the collector (``gc.unfreeze``: the caller's process goes on),
    unless a user asked ``keep_frozen`` (the program ends: the interpreter's last collection then
    skips them too) or the caller had frozen objects of its own before (which cannot be told
    from ours).
    """
    with _LOCK:
        if not _Hook.users:
            _Hook.original, _Hook.frozen_before = builtins.__import__, gc.get_freeze_count()
            _Hook.keep = False
            builtins.__import__ = _importing
        _Hook.users += 1
        _Hook.keep = _Hook.keep or keep_frozen
    try:
        yield
    finally:
        with _LOCK:
            _Hook.users -= 1
            if not _Hook.users:
                builtins.__import__ = _Hook.original
                if not _Hook.keep and not _Hook.frozen_before:
                    gc.unfreeze()
