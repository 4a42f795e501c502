"""The registry of effects: the built-ins, installed plugins and a user's file, by name.

It registers effects and looks them (and their terms) up, nothing else: the terms' model arithmetic
is :mod:`aacmm_pin.effects.forward`'s, the ``parameters.json`` file
:mod:`aacmm_pin.effects.parameters_file`'s. Importing it registers :func:`term_from_key` as the
model layer's term lookup (:data:`aacmm_pin.model.parameters.TERM_LOOKUP`): parameters made from a
file or a dict carry their extensions' terms from then on.

Effects come from three places, in this order: the built-ins of :mod:`aacmm_pin.effects`, the
installed packages that offer an entry point in the group ``aacmm_pin.effects`` (each entry point
loads an :class:`~aacmm_pin.effects.base.Effect` instance or class, or a list of them), and a
Python file a command is given (``--effects-file FILE``, :func:`load_effect_file`), which calls
:func:`register_effect` itself. ``parameters.json`` names the plugin that brings the effect of each
of its extensions (``"plugins": {plugin: [term keys]}``, plugin being the distribution name or the
effects file's path, :func:`plugins_of`).
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import sys
import threading
from collections.abc import Iterable
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from aacmm_pin.data.columns import set_effect_reads
from aacmm_pin.effects.base import SOURCE_OF, Effect, Term
from aacmm_pin.effects.builtin.backlash import Backlash
from aacmm_pin.effects.builtin.compliance import Compliance
from aacmm_pin.effects.builtin.crosstalk import Crosstalk
from aacmm_pin.effects.builtin.encoder import Encoder
from aacmm_pin.effects.builtin.lateral_compliance import LateralCompliance
from aacmm_pin.effects.builtin.rtest import RTest
from aacmm_pin.effects.builtin.thermal import Thermal
from aacmm_pin.effects.builtin.tool import Tool
from aacmm_pin.errors import AacmmError
from aacmm_pin.model.parameters import TERM_LOOKUP

GROUP = "aacmm_pin.effects"
"""The entry-point group through which installed packages offer effects."""
BUILTIN = "aacmm_pin"
"""The plugin name of the built-in effects."""
LIBRARY: dict[str, Effect] = {}
"""Registered effects by name (built-ins first); :func:`register_effect` adds more; read it
through :func:`library`, which loads the installed plugins first."""
_SOURCE: dict[str, str] = {}
_LOADED: list[bool] = []
_LOCK = threading.RLock()
_FILES: dict[str, str] = {}


class EffectNotFound(AacmmError, KeyError):
    """A calibration or command names an effect (or term) that is not registered."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def register_effect(effect: Effect | type[Effect], plugin: str | None = None, *,
                    replace: bool = False) -> Effect:
    """Add an effect to the library; return it.

    Args:
        effect: an effect instance, or an effect class (instantiated without arguments).
        plugin: where it comes from, written into ``parameters.json`` so that another process can
            say what to install: a distribution name, or a file path (default: the module of the
            effect's class; a script's path for a class defined in the script run).
        replace: allow replacing an effect of the same name from another source (a built-in's
            keys would otherwise be evaluated by someone else's code without a word).

    Raises:
        AacmmError: if it is no named effect, or its name is taken by an effect of another source.
    """
    if isinstance(effect, type):
        effect = effect()
    if not isinstance(effect, Effect) or not effect.name:
        raise AacmmError(f"register_effect: an aacmm_pin.effects.Effect with a name expected, got "
                         f"{effect!r}")
    source = plugin or _module_of(type(effect))
    held = _SOURCE.get(effect.name)
    if effect.name in LIBRARY and held != source and not replace:
        raise AacmmError(f"effect {effect.name!r} of {source!r}: the name is taken by the effect of "
                         f"{held!r} (rename it, or register_effect(..., replace=True))")
    LIBRARY[effect.name] = effect
    _SOURCE[effect.name] = source
    return effect


def _module_of(cls: type) -> str:
    """Return the module that defines ``cls``; for a script run or an effects file, its path."""
    if cls.__module__ in _FILES:
        return _FILES[cls.__module__]
    if cls.__module__ == "__main__":
        main = getattr(sys.modules.get("__main__"), "__file__", None)
        if main:
            return str(Path(main).resolve())
    return cls.__module__


def _columns_read() -> set[str]:
    """Return the per-sample columns the registered effects read, installed plugins loaded."""
    return {name for effect in library().values() for name in effect.reads}


set_effect_reads(_columns_read)
SOURCE_OF.append(lambda name: _SOURCE.get(name, ""))  # a term's error names its effect's plugin
for _builtin in (Encoder, Compliance, LateralCompliance, Thermal, Backlash, Crosstalk, RTest, Tool):
    register_effect(_builtin, BUILTIN)


def _is_effect(item: Any) -> bool:
    return isinstance(item, Effect) or (isinstance(item, type) and issubclass(item, Effect))


def _from_entry_point(value: Any, plugin: str) -> None:
    """Register what an entry point loads: effects or classes, a list, or a function.

    A function registers its effects itself, or returns them.
    """
    if callable(value) and not _is_effect(value):
        value = value()
        if value is None:
            return
    items = value if isinstance(value, (list, tuple)) else [value]
    for item in items:
        if not _is_effect(item):
            raise AacmmError(f"an Effect, an Effect class, a list of them or a function expected, "
                             f"got {item!r}")
        register_effect(item, plugin)


def load_plugins() -> None:
    """Register the effects of every installed package's ``aacmm_pin.effects`` entry point (once).

    Thread-safe; a failure is raised again on the next call (the plugins count as loaded only
    when all of them loaded).

    Raises:
        AacmmError: naming the entry point and its package when one fails to load.
    """
    if _LOADED:
        return
    with _LOCK:
        if _LOADED:
            return
        for ep in entry_points(group=GROUP):
            plugin = ep.dist.name if ep.dist is not None else ep.value.split(":")[0]
            try:
                _from_entry_point(ep.load(), plugin)
            except Exception as exc:  # a broken plugin names itself, whatever it raised
                raise AacmmError(f"effect plugin {plugin!r} (entry point {ep.name} = {ep.value}) "
                                 f"failed to load: {_one_line(exc)}") from exc
        _LOADED.append(True)


def _one_line(exc: BaseException) -> str:
    """Return ``Type: first line of the message`` of an exception."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def load_effect_file(path: str | Path) -> list[str]:
    """Run a Python file that registers effects; return the names it registered.

    A file that registers nothing itself (a plugin's module, written for its entry point) has
    every :class:`Effect` subclass it defines registered.

    Raises:
        AacmmError: if the file does not exist or fails to run (naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise AacmmError(f"{path}: no such effects file")
    before = dict(LIBRARY)
    digest = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:16]
    name = f"aacmm_pin_user_effects_{digest}"  # the same in every process: terms unpickle
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise AacmmError(f"{path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look their module up
    _FILES[name] = str(path.resolve())  # its effects' plugin, unless it names another
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        raise AacmmError(f"{path}: the effects file failed: {_one_line(exc)}") from exc
    new = [n for n, e in LIBRARY.items() if before.get(n) is not e]
    if not new:
        for cls in vars(module).values():
            if isinstance(cls, type) and issubclass(cls, Effect) and cls.__module__ == name \
                    and cls.name and not inspect.isabstract(cls):
                new.append(register_effect(cls).name)
    return new


def library() -> dict[str, Effect]:
    """Return every registered effect by name, installed plugins loaded."""
    load_plugins()
    return LIBRARY


def default_effects() -> list[str]:
    """Return the names of the effects tried when no list is given (:attr:`Effect.by_default`)."""
    return [name for name, effect in library().items() if effect.by_default]


def plugin_of(effect: str) -> str:
    """Return where an effect comes from (``aacmm_pin``, a distribution name or a file path)."""
    return _SOURCE.get(effect, "")


def term_from_key(key: str) -> Term:
    """Return the term a ``parameters.json`` extensions key names.

    Raises:
        EffectNotFound: if no registered effect knows the key.
    """
    for effect in library().values():
        term = effect.term(key)
        if term is not None:
            return term
    raise EffectNotFound(f"{key!r} is no term of a registered effect (the effects are "
                         f"{', '.join(LIBRARY)}; a plugin's effects load with its package or "
                         f"--effects-file)")


def terms_of(extensions: Iterable[str]) -> list[Term]:
    """Return the terms named by a parameters' extensions (keys of ``Parameters.extensions``)."""
    return [term_from_key(k) for k in extensions]


def effect_names(terms: Iterable[Term]) -> list[str]:
    """Return the distinct effect names of some terms, in order."""
    return list(dict.fromkeys(t.effect for t in terms))


def plugins_of(terms: Iterable[Term]) -> dict[str, list[str]]:
    """Return plugin -> the keys of its terms, for the terms whose effects are not built in.

    ``parameters.json`` keeps it as ``"plugins"``, so that a process without the plugin can say
    which one to install.
    """
    out: dict[str, list[str]] = {}
    for t in terms:
        if plugin_of(t.effect) != BUILTIN:
            out.setdefault(plugin_of(t.effect) or t.effect, []).append(t.key)
    return out


TERM_LOOKUP[:] = [term_from_key]  # parameters made from now on carry their extensions' terms
