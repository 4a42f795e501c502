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
from collections.abc import Iterator
from typing import Any


@contextlib.contextmanager
def imports_uncollected(keep_frozen: bool = False) -> Iterator[None]:
    """Within: ``import`` statements run without the collector; what they load is frozen after.

    Only an import that loads a module freezes (a statement naming loaded modules costs a length
    check); an import inside an import, or one while the collector is off (the caller's own
    ``gc.disable()``), changes nothing. ``builtins.__import__`` is restored on exit, and the frozen
    objects are returned to the collector (``gc.unfreeze``: the caller's process goes on), unless
    ``keep_frozen`` (the program ends: the interpreter's last collection then skips them too) or
    the caller had frozen objects of its own before (which cannot be told from ours).
    """
    original = builtins.__import__
    frozen_before = gc.get_freeze_count()

    def importing(name: str, globals: Any = None, locals: Any = None, fromlist: Any = (),
                  level: int = 0) -> Any:
        if not gc.isenabled():
            return original(name, globals, locals, fromlist, level)
        loaded = len(sys.modules)
        gc.disable()
        try:
            return original(name, globals, locals, fromlist, level)
        finally:
            if len(sys.modules) != loaded:
                gc.freeze()
            gc.enable()

    builtins.__import__ = importing
    try:
        yield
    finally:
        builtins.__import__ = original
        if not keep_frozen and not frozen_before:
            gc.unfreeze()
