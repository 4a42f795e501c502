"""``parameters.json`` with its extension terms: read with their terms checked, written with plugins.

The file's fields are read and written by :mod:`aacmm_pin.model.parameters` (its JSON form, with
every key of ``extensions`` made into its term where the parameters are made); this module adds
what needs the effect library: the check that every extension names a registered term with its
number of values (:func:`check_extensions`), and the ``"plugins"`` entry, ``{plugin: [term
keys]}`` for the terms whose effects are not built in (:func:`with_plugins`), so that a process
without the plugin's effect says which plugin to install (or which ``--effects-file`` to pass).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from aacmm_pin.effects.base import Term
from aacmm_pin.effects.registry import EffectNotFound, plugin_of, plugins_of
from aacmm_pin.effects.term_axes import axes_problem
from aacmm_pin.errors import FileFormatError, Problem
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.parameters import read_parameters as read_file
from aacmm_pin.model.parameters import write_parameters as write_file

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm


def read_parameters(path: str | Path) -> Parameters:
    """Read ``parameters.json`` (or a calibration folder) and check its extensions' terms.

    :func:`aacmm_pin.model.parameters.read_parameters` with :func:`check_extensions`: every key of
    ``extensions`` must be a term of a registered effect (a plugin's effect is named with its
    plugin).

    Raises:
        FileFormatError: as :func:`aacmm_pin.model.parameters.read_parameters`, or naming the
            extension key whose effect is not registered.
    """
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


def _term(params: Parameters, key: str) -> Term | None:
    """Return the term of an extension key (looked up when the parameters were made), or None."""
    term = params.extension_terms.get(key)
    return term if isinstance(term, Term) else None


def with_plugins(params: Parameters) -> Parameters:
    """Return the parameters with ``extra["plugins"]`` naming the plugin of every extension's effect.

    ``{plugin: [term keys]}`` for the terms of effects that are not built in (:func:`plugins_of`);
    no entry when every term is built in. A key whose effect is not registered here keeps the
    plugin the parameters named for it.
    """
    old = needed_plugins(params)
    plugins: dict[str, list[str]] = {}
    for key in params.extensions:
        term = _term(params, key)
        found = (plugins_of([term]) if term is not None
                 else {old[key]: [key]} if key in old else {})
        for plugin, keys in found.items():
            plugins.setdefault(plugin, []).extend(keys)
    extra = {k: v for k, v in params.extra.items() if k != "plugins"}
    return params.replace(extra={**extra, "plugins": plugins} if plugins else extra)


def write_parameters(params: Parameters, path: str | Path) -> None:
    """Write ``parameters.json``, naming the plugins its extensions need (``"plugins"``).

    :func:`aacmm_pin.model.parameters.write_parameters` of :func:`with_plugins`: a process without
    a plugin's effect then says which plugin to install (:func:`check_extensions`).
    """
    write_file(with_plugins(params), path)


def _missing_plugins(params: Parameters, needed: dict[str, str], keys: Iterable[str],
                     where: object) -> str:
    """Return one line naming the extension keys whose plugin is not loaded, and the plugins."""
    by_plugin: dict[str, list[str]] = {}
    for key in keys:
        by_plugin.setdefault(needed[key], []).append(key)
    parts = []
    for plugin, its in by_plugin.items():
        how = (f"pass --effects-file {plugin}" if plugin.endswith(".py") else
               f"install the package {plugin} (or pass --effects-file FILE)")
        here = [plugin_of(term.effect) for k in its if (term := _term(params, k)) is not None]
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
        term = _term(params, key)
        if term is None or (key in needed and plugin_of(term.effect) != needed[key]):
            # not registered, or made with a plugin's effect that replaced this one: another model
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
        raise EffectNotFound(_missing_plugins(params, needed, unloaded, where))
    if problems:
        raise FileFormatError(problems)
