"""The registry of effects: the built-ins, installed plugins and a user's file, by name.

Effects come from three places, in this order: the built-ins of :mod:`aacmm_pin.effects`, the
installed packages that offer an entry point in the group ``aacmm_pin.effects`` (each entry point
loads an :class:`~aacmm_pin.effects.base.Effect` instance or class, or a list of them), and a
Python file a command is given (``--effects-file FILE``, :func:`load_effect_file`), which calls
:func:`register_effect` itself. ``parameters.json`` names the plugin that brings the effect of each
of its extensions (``"plugins": {plugin: [term keys]}``, :func:`write_parameters`, plugin being the
distribution name or the effects file's path); reading it where that effect is not registered is
a one-line error naming the key and the plugin (:func:`check_extensions`).
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import sys
import threading
from collections.abc import Iterable, Mapping
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aacmm_pin.data.columns import set_effect_reads
from aacmm_pin.effects.base import SOURCE_OF, Adjustment, Effect, Term
from aacmm_pin.effects.builtin.backlash import Backlash
from aacmm_pin.effects.builtin.compliance import Compliance
from aacmm_pin.effects.builtin.crosstalk import Crosstalk
from aacmm_pin.effects.builtin.encoder import Encoder
from aacmm_pin.effects.builtin.lateral_compliance import LateralCompliance
from aacmm_pin.effects.builtin.rtest import RTest
from aacmm_pin.effects.builtin.thermal import Thermal
from aacmm_pin.effects.builtin.tool import Tool
from aacmm_pin.errors import AacmmError, ArgumentError, FileFormatError, Problem

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.parameters import Parameters
    from aacmm_pin.model.samples import Samples

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


def axes_problem(term: Term, arm: Arm) -> str | None:
    """Return why a term does not fit the arm's axes (an axis beyond it), or None if it does.

    One line naming the term and the arm's axes, e.g. ``'compliance[A7]' acts on axis 7; the arm
    ur5 has 6 axes, A1..A6 (shoulder_pan_joint .. wrist_3_joint)``.
    """
    beyond = [a for a in term.axes if not 1 <= a <= arm.n_axes]
    if not beyond:
        return None
    plain = list(arm.axis_names) == [f"A{a}" for a in range(1, arm.n_axes + 1)]
    names = "" if plain else f" ({arm.axis_names[0]} .. {arm.axis_names[-1]})"
    return (f"{term.key!r} acts on axis {beyond[0]}; the arm {arm.name} has {arm.n_axes} axes, "
            f"A1..A{arm.n_axes}{names}")


def check_terms(terms: Iterable[Term], arm: Arm, where: str) -> None:
    """Check that every term acts on axes of the arm.

    Args:
        terms: the terms (e.g. ``identify``'s ``extensions``, ``--terms``).
        arm: the arm they are to be estimated on.
        where: what gave them, named first in the message (``--terms``, ``extensions``).

    Raises:
        ArgumentError: one line naming ``where``, the first term beyond the arm and its axes.
    """
    for term in terms:
        if (why := axes_problem(term, arm)) is not None:
            raise ArgumentError(f"{where}: {why}")


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


def adjustment(extensions: Mapping[str, np.ndarray], samples: Samples, n_axes: int) -> Adjustment:
    """Return how the extension terms change the arm at the samples (see :class:`Adjustment`)."""
    return terms_adjustment([(term_from_key(key), np.asarray(values, dtype=float))
                             for key, values in extensions.items()], samples, n_axes)


def terms_adjustment(terms: Iterable[tuple[Term, np.ndarray]], samples: Samples, n_axes: int
                     ) -> Adjustment:
    """Return how terms with their values change the arm at the samples (see :class:`Adjustment`).

    :func:`adjustment` with the terms looked up once (the runtime object holds them).
    """
    out = Adjustment(samples.n, n_axes)
    for term, values in terms:
        term.adjust(values, samples, out)
    return out


def measurement_shift(terms: Iterable[Term], extensions: Mapping[str, np.ndarray], samples: Samples
                      ) -> np.ndarray:
    """Return the terms' change of the measured point, shape (N, 3), m."""
    out = np.zeros((samples.n, 3))
    for t in terms:
        shift = t.shift(extensions[t.key], samples)
        if shift is not None:
            out += shift
    return out


def read_parameters(path: str | Path) -> Parameters:
    """Read ``parameters.json`` (or a calibration folder) and check its extensions' terms.

    :func:`aacmm_pin.model.parameters.read_parameters` with :func:`check_extensions`: every key of
    ``extensions`` must be a term of a registered effect (a plugin's effect is named with its
    plugin).

    Raises:
        FileFormatError: as :func:`aacmm_pin.model.parameters.read_parameters`, or naming the
            extension key whose effect is not registered.
    """
    from aacmm_pin.model.parameters import read_parameters as read_file

    params = read_file(path)
    file = Path(path)
    check_extensions(params, None, file / "parameters.json" if file.is_dir() else file)
    return params


def needed_plugins(params: Parameters) -> dict[str, str]:
    """Return extension key -> plugin, as the parameters' ``"plugins"`` entry names them."""
    plugins = params.extra.get("plugins")
    if not isinstance(plugins, dict):
        return {}
    return {str(k): str(p) for p, keys in plugins.items() if isinstance(keys, list) for k in keys}


def with_plugins(params: Parameters) -> Parameters:
    """Return the parameters with ``extra["plugins"]`` naming the plugin of every extension's effect.

    ``{plugin: [term keys]}`` for the terms of effects that are not built in (:func:`plugins_of`);
    no entry when every term is built in. A key whose effect is not registered here keeps the
    plugin the parameters named for it.
    """
    old = needed_plugins(params)
    plugins: dict[str, list[str]] = {}
    for key in params.extensions:
        try:
            found = plugins_of([term_from_key(key)])
        except EffectNotFound:
            found = {old[key]: [key]} if key in old else {}
        for plugin, keys in found.items():
            plugins.setdefault(plugin, []).extend(keys)
    extra = {k: v for k, v in params.extra.items() if k != "plugins"}
    return params.replace(extra={**extra, "plugins": plugins} if plugins else extra)


def write_parameters(params: Parameters, path: str | Path) -> None:
    """Write ``parameters.json``, naming the plugins its extensions need (``"plugins"``).

    :func:`aacmm_pin.model.parameters.write_parameters` of :func:`with_plugins`: a process without
    a plugin's effect then says which plugin to install (:func:`check_extensions`).
    """
    from aacmm_pin.model.parameters import write_parameters as write_file

    write_file(with_plugins(params), path)


def _registered(key: str) -> bool:
    """Whether a registered effect knows the term ``key``."""
    try:
        term_from_key(key)
    except EffectNotFound:
        return False
    return True


def _missing_plugins(needed: dict[str, str], keys: Iterable[str], where: object) -> str:
    """Return one line naming the extension keys whose plugin is not loaded, and the plugins."""
    by_plugin: dict[str, list[str]] = {}
    for key in keys:
        by_plugin.setdefault(needed[key], []).append(key)
    parts = []
    for plugin, its in by_plugin.items():
        how = (f"pass --effects-file {plugin}" if plugin.endswith(".py") else
               f"install the package {plugin} (or pass --effects-file FILE)")
        here = [plugin_of(term_from_key(k).effect) for k in its if _registered(k)]
        other = (f" (the effect registered here is {here[0]!r}'s, another model: the calibration "
                 f"was made with the plugin's, which replaced it)" if here else "")
        parts.append(f"extensions {', '.join(its)} need the effect plugin {plugin!r}, not loaded "
                     f"here{other}: {how}")
    return f"{where}: " + "; ".join(parts)


def check_extensions(params: Parameters, arm: Arm | None = None, path: str | Path | None = None
                     ) -> None:
    """Check that every extension names a registered term with its number of values (and axes).

    A calibration written with a plugin's effect names the plugin (``parameters.json``
    ``"plugins"``); when the effect is not registered here, the error is one line naming the key
    and the plugin to install (or the file to pass with ``--effects-file``).

    Raises:
        EffectNotFound: one line naming the file, the keys and the plugins not loaded here.
        FileFormatError: listing every other problem, naming the file and the key.
    """
    where = path if path is not None else params.arm
    needed = needed_plugins(params)
    problems: list[Problem] = []
    unloaded = []
    for key, values in params.extensions.items():
        try:
            term = term_from_key(key)
            if key in needed and plugin_of(term.effect) != needed[key]:
                # made with a plugin's effect that replaced this one: another model, not it
                unloaded.append(key)
                continue
        except EffectNotFound:
            if key in needed:
                unloaded.append(key)
            else:
                problems.append(Problem(where, None, f"extensions.{key}",
                                        "not a term of the effect library (e.g. compliance[A2], "
                                        "lateral_compliance[A2], thermal, backlash[A3], crosstalk[A2<-A3], "
                                        "encoder_harmonic[A4], rtest)"))
            continue
        if values.size != len(term.names):
            problems.append(Problem(where, None, f"extensions.{key}",
                                    f"needs {len(term.names)} finite numbers, got {values.tolist()!r}"))
        elif arm is not None and (why := axes_problem(term, arm)) is not None:
            problems.append(Problem(where, None, f"extensions.{key}", why))
    if unloaded:
        raise EffectNotFound(_missing_plugins(needed, unloaded, where))
    if problems:
        raise FileFormatError(problems)
