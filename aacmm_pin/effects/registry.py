"""The registry of effects: the built-ins, installed plugins and a user's file, by name.

Effects come from three places, in this order: the built-ins of :mod:`aacmm_pin.effects`, the
installed packages that offer an entry point in the group ``aacmm_pin.effects`` (each entry point
loads an :class:`~aacmm_pin.effects.base.Effect` instance or class, or a list of them), and a
Python file a command is given (``--effects-file FILE``, :func:`load_effect_file`), which calls
:func:`register_effect` itself. ``parameters.json`` names the effects its extensions need beside
the plugin that brings each one (:func:`plugins_of`); a missing one is a one-line error naming it.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Iterable, Mapping
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aacmm_pin.effects.backlash import Backlash
from aacmm_pin.effects.base import Adjustment, Effect, Term
from aacmm_pin.effects.compliance import Compliance
from aacmm_pin.effects.crosstalk import Crosstalk
from aacmm_pin.effects.encoder import Encoder
from aacmm_pin.effects.lateral_compliance import LateralCompliance
from aacmm_pin.effects.rtest import RTest
from aacmm_pin.effects.thermal import Thermal
from aacmm_pin.effects.tool import Tool
from aacmm_pin.errors import AacmmError, FileFormatError, Problem

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


class EffectNotFound(AacmmError, KeyError):
    """A calibration or command names an effect (or term) that is not registered."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def register_effect(effect: Effect | type[Effect], plugin: str | None = None) -> Effect:
    """Add (or replace) an effect of the library; return it.

    Args:
        effect: an effect instance, or an effect class (instantiated without arguments).
        plugin: where it comes from, written into ``parameters.json`` so that another process can
            say what to install: a distribution name, or a file path (default: the caller's module).
    """
    if isinstance(effect, type):
        effect = effect()
    if not isinstance(effect, Effect) or not effect.name:
        raise AacmmError(f"register_effect: an aacmm_pin.effects.Effect with a name expected, got "
                         f"{effect!r}")
    LIBRARY[effect.name] = effect
    _SOURCE[effect.name] = plugin or type(effect).__module__
    return effect


for _builtin in (Encoder, Compliance, LateralCompliance, Thermal, Backlash, Crosstalk, RTest, Tool):
    register_effect(_builtin, BUILTIN)


def _from_entry_point(value: Any, plugin: str) -> None:
    items = value if isinstance(value, (list, tuple)) else [value]
    for item in items:
        if isinstance(item, Effect) or (isinstance(item, type) and issubclass(item, Effect)):
            register_effect(item, plugin)
        elif callable(item):  # a function that registers its effects itself
            item()


def load_plugins() -> None:
    """Register the effects of every installed package's ``aacmm_pin.effects`` entry point (once).

    Raises:
        AacmmError: naming the entry point and its package when one fails to load.
    """
    if _LOADED:
        return
    _LOADED.append(True)
    for ep in entry_points(group=GROUP):
        plugin = ep.dist.name if ep.dist is not None else ep.value.split(":")[0]
        try:
            _from_entry_point(ep.load(), plugin)
        except Exception as exc:  # a broken plugin names itself, whatever it raised
            raise AacmmError(f"effect plugin {plugin!r} (entry point {ep.name} = {ep.value}) "
                             f"failed to load: {type(exc).__name__}: {exc}") from exc


def load_effect_file(path: str | Path) -> list[str]:
    """Run a Python file that registers effects; return the names it registered.

    Raises:
        AacmmError: if the file does not exist or fails to run (naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise AacmmError(f"{path}: no such effects file")
    before = dict(LIBRARY)
    name = f"aacmm_pin_user_effects_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise AacmmError(f"{path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look their module up
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        raise AacmmError(f"{path}: the effects file failed: {type(exc).__name__}: {exc}") from exc
    new = [n for n, e in LIBRARY.items() if before.get(n) is not e]
    for n in new:
        _SOURCE[n] = str(path.resolve())
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


def adjustment(extensions: Mapping[str, np.ndarray], samples: Samples, n_axes: int) -> Adjustment:
    """Return how the extension terms change the arm at the samples (see :class:`Adjustment`)."""
    out = Adjustment(samples.n, n_axes)
    for key, values in extensions.items():
        term_from_key(key).adjust(np.asarray(values, dtype=float), samples, out)
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


def check_extensions(params: Parameters, arm: Arm | None = None, path: str | Path | None = None
                     ) -> None:
    """Check that every extension names a registered term with its number of values (and axes).

    A calibration written with a plugin's effect names the plugin (``parameters.json``
    ``"plugins"``); when the effect is not registered here, the error says which plugin to install.

    Raises:
        FileFormatError: listing every problem, naming the file and the key.
    """
    where = path if path is not None else params.arm
    plugins = params.extra.get("plugins")
    needed = {str(k): str(p) for p, keys in plugins.items() if isinstance(keys, list) for k in keys
              } if isinstance(plugins, dict) else {}
    problems: list[Problem] = []
    for key, values in params.extensions.items():
        try:
            term = term_from_key(key)
        except EffectNotFound:
            hint = (f"its effect comes from the plugin {needed[key]!r}, not loaded here: install that "
                    f"package, or pass --effects-file FILE" if key in needed else
                    "not a term of the effect library (e.g. compliance[A2], lateral_compliance[A2], "
                    "thermal, backlash[A3], crosstalk[A2<-A3], encoder_harmonic[A4], rtest)")
            problems.append(Problem(where, None, f"extensions.{key}", hint))
            continue
        if values.size != len(term.names):
            problems.append(Problem(where, None, f"extensions.{key}",
                                    f"needs {len(term.names)} finite numbers, got {values.tolist()!r}"))
        elif arm is not None and any(not 1 <= a <= arm.n_axes for a in term.axes):
            problems.append(Problem(where, None, f"extensions.{key}",
                                    f"the arm has axes 1..{arm.n_axes}"))
    if problems:
        raise FileFormatError(problems)
