r"""The effect contract at run time: declared columns, and a term's columns against its model.

Two checks, both cheap, for every effect and term (built-in, an installed plugin's, a file's):

* **Declared columns** (:func:`usable_effects`): an effect is asked nothing (``candidates``,
  ``offered``, ``variables``) on samples that lack a column it declares (:attr:`Effect.reads`); it
  is left out and listed (:class:`LeftOut`, e.g. ``thermal (no column temp_c)``), never an
  error. Every place that asks effects goes through this one function.
* **Columns against the forward change** (:func:`check_once`): the first time a term is used in a
  process (by its effect's plugin and its key), its Jacobian columns (``term.columns``) on
  :data:`SAMPLES` of the samples are compared with central differences of its forward change: the
  stylus centres (:func:`aacmm_pin.model.kinematics.stylus_positions`) with the term's
  :class:`~aacmm_pin.model.kinematics.Adjustment` (``term.adjust``) at its values :math:`\pm h`,
  plus its change of the measured point (``term.shift``); its parameters move together along one
  direction of random signs and weights, each alone only to name the one whose column is wrong
  (and the four models in one call of the kinematics, the Jacobians of an arm no term changes
  kept for the next term: ~5 ms a term). A term whose columns disagree beyond the
  differences' own error is refused (:class:`ContractBroken`, one line naming the term, its effect
  and its plugin). The check is generic (no per-kind code): any term that acts through
  ``adjust``/``shift`` and gives ``columns`` is covered. Terms whose values are not extensions (an
  encoder map: its nodes live in the maps) are skipped; the contract test checks them.

The step and tolerance (:func:`disagreement`): :math:`h` is :data:`STEP` of the parameter's
plausible size. Two central differences, :math:`D_h` and :math:`D_{2h}`, give the derivative
:math:`R = (4 D_h - D_{2h}) / 3` (Richardson: truncation :math:`O(h^4)`); the truncation error of
:math:`D_h` is :math:`(D_{2h} - D_h) / 3`, so :math:`|D_{2h} - D_h|` bounds the truncation of
:math:`R` with a factor of 3 to spare. Rounding: every stylus centre carries at most
:data:`ROUNDING_ULPS` ulps of its size :math:`|p|`, which :math:`R` turns into at most
:math:`1.5 \cdot \text{ulps} \cdot \epsilon |p| / h` (and the columns' own rounding, the same ulps
of their size). The tolerance is their sum; a term without a forward change (the issue's plugin:
columns, no ``adjust``) differs by its whole column, ~1e6 times this on a plausible term; the
built-in terms differ by 0.09 of it at most (every candidate on the effects campaign).
"""

from __future__ import annotations

import dataclasses
import functools
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from aacmm_pin.effects.base import Effect, PluginOutputError, Term
from aacmm_pin.effects.calibrated import needs_tilts
from aacmm_pin.effects.registry import library, plugin_of
from aacmm_pin.errors import AacmmError
from aacmm_pin.model import kinematics
from aacmm_pin.model.kinematics import Adjustment, StylusJacobians

if TYPE_CHECKING:
    from aacmm_pin.model.parameters import Parameters
    from aacmm_pin.model.samples import Samples

SAMPLES = 4
"""Samples the columns are checked on (spread over the samples given)."""
STEP = 1e-3
"""Central differences' step, as a fraction of each parameter's plausible size."""
ROUNDING_ULPS = 64.0
"""Rounding error of a stylus centre, in ulps of its size: a chain of up to ~16 rigid transforms
(base, the joints and their error frames, the tool) each adding a few ulps."""
FRAME = "mt"
"""The frame the check works in: the fit's and the scorers' (the MT-CS, with X0)."""

T = TypeVar("T")
_CHECKED: set[tuple[Any, ...]] = set()
_LOCK = threading.Lock()
_STYLUS: list[tuple[tuple[Any, ...], StylusJacobians]] = []
"""The last stylus Jacobians of an arm no term changes: (parameters, readouts, tools, tilts)."""


# ------------------------------------------------------------------ declared columns
@dataclass(frozen=True)
class LeftOut:
    """An effect not asked on these samples: they lack columns it declares (``Effect.reads``)."""

    effect: str
    """The effect's name."""
    columns: tuple[str, ...]
    """The declared columns the samples do not have, as in the files (``temp_wrist_c``)."""

    def __str__(self) -> str:
        """``thermal (no column temp_c)``."""
        return f"{self.effect} (no column{'s' if len(self.columns) > 1 else ''} " \
               f"{', '.join(self.columns)})"

    def to_dict(self) -> dict[str, Any]:
        """Return ``discovery.json``'s entry: the effect and the columns missing."""
        return {"effect": self.effect, "missing_columns": list(self.columns)}


def missing_columns(effect: Effect, samples: Samples) -> tuple[str, ...]:
    """Return the columns ``effect`` declares (:attr:`Effect.reads`) that the samples lack."""
    return tuple(name for name in effect.reads if not samples.has_column(name))


def usable_effects(effects: Iterable[Effect], samples: Samples
                   ) -> tuple[list[Effect], list[LeftOut]]:
    """Return the effects that may be asked on these samples, and those left out (and why).

    An effect is asked nothing (``candidates``, ``offered``, ``variables``) on samples without a
    column it declares: it is left out, in order, never an error.
    """
    kept, left = [], []
    for effect in effects:
        if missing := missing_columns(effect, samples):
            left.append(LeftOut(effect.name, missing))
        else:
            kept.append(effect)
    return kept, left


# ------------------------------------------------------------------ columns vs forward change
class ContractBroken(PluginOutputError):
    """A term's columns disagree with central differences of its forward change (adjust, shift)."""


def check_once(terms: Iterable[Term], samples: Samples, params: Parameters) -> None:
    """Check each term's columns against its forward change, once per process (see module doc).

    A term is known by its effect's plugin, its key, its registered effect (an effects file run
    again registers a new one) and its definition (class and fields: a frame term's frame, the
    axes, the sizes): checked the first time it comes, then passed at the cost of a set lookup.

    Args:
        terms: the terms about to be evaluated (a fit's, a scorer's candidate).
        samples: the samples they are evaluated on (N >= 1); :data:`SAMPLES` spread rows are used.
        params: the parameters at which they are evaluated (the term's values there, zero when
            the parameters have none; the other extensions are left out of the check).

    Raises:
        ContractBroken: one line naming the term, its effect and its plugin, for columns that
            differ from the central differences of the forward change.
        PluginOutputError: naming the term, for a forward change or columns that raise or have
            the wrong shape.
        MissingColumn: as the term's own code raises it, for samples without its column.
    """
    for term in terms:
        key = (plugin_of(term.effect), term.key, library().get(term.effect), type(term), repr(term))
        if key in _CHECKED:
            continue
        check_term(term, samples, params)
        with _LOCK:
            _CHECKED.add(key)


def check_term(term: Term, samples: Samples, params: Parameters, n: int = SAMPLES) -> None:
    """Check one term's columns against central differences of its forward change (every time).

    See :func:`check_once` for the arguments and errors. The term's parameters move together, along
    one direction of random signs and weights (a wrong column cannot cancel in it but by chance);
    only when that disagrees is each parameter checked alone, to name the one whose column is
    wrong. A term whose values are not extensions (an encoder map: its nodes live in the maps) is
    not checked here (the contract test does).
    """
    if not term.is_extension or not samples.n:
        return
    rows = np.unique(np.linspace(0, samples.n - 1, min(n, samples.n)).round().astype(int))
    sub = samples.select(rows)
    k = len(term.names)
    values = np.asarray(params.extensions.get(term.key, np.zeros(k)), dtype=float).reshape(-1)
    at = params.replace(extensions={term.key: values}, extension_terms={term.key: term})
    cols = _columns(term, sub, at, values, params)
    sizes = np.abs(np.broadcast_to(np.asarray(term.sizes(sub.arm.sizes), dtype=float), (k,)))
    steps = STEP * np.where(sizes > 0, sizes, 1.0)
    plain = params.replace(extensions={}, extension_terms={})
    rng = np.random.default_rng(k)
    direction = steps * rng.choice([-1.0, 1.0], k) * rng.uniform(0.5, 1.5, k)
    if disagreement(cols @ direction, _points(term, plain, sub, values, direction), 1.0) is None:
        return
    for j in range(k):
        alone = np.where(np.arange(k) == j, steps, 0.0)
        why = disagreement(cols[:, :, j], _points(term, plain, sub, values, alone), steps[j])
        if why is not None:
            raise ContractBroken(term, f"its columns disagree with its forward change (adjust, "
                                       f"shift) for {term.names[j]}: {why} on {sub.n} samples: "
                                       "columns and forward change must describe one model")
    raise ContractBroken(term, f"its columns disagree with its forward change (adjust, shift) "
                               f"for its {k} parameters together on {sub.n} samples, though for "
                               "none alone: columns and forward change must describe one model")


def _columns(term: Term, samples: Samples, params: Parameters, values: np.ndarray,
             base: Parameters) -> np.ndarray:
    """Return the term's columns at ``params`` (its values ``values``), checked: (n, 3, k)."""
    stylus = _stylus(term, samples, params, values, base)
    cols = _guarded(term, "its columns", lambda: np.asarray(
        term.columns(samples, stylus, params), dtype=float))
    if cols.shape != (samples.n, 3, values.size):
        raise PluginOutputError(term, f"its columns have shape {cols.shape}, expected "
                                      f"({samples.n}, 3, {values.size}) for {samples.n} samples "
                                      f"and {values.size} parameters")
    return cols


def _stylus(term: Term, samples: Samples, params: Parameters, values: np.ndarray,
            base: Parameters) -> StylusJacobians:
    """Return the stylus Jacobians with the term's change of the arm at its values.

    Where that change leaves the arm as it is (a term at zero, e.g. a candidate), the last ones of
    these samples and ``base`` parameters serve again: the terms a fit or a scorer brings in one
    go cost one evaluation of the Jacobians.
    """
    change = _guarded(term, "its forward change",
                      functools.partial(_adjustment, term, values, samples))
    key = (base, samples.q.tobytes(), None if samples.tool is None else samples.tool.tobytes(),
           needs_tilts([term]))
    still = _unchanged(change)
    with _LOCK:
        if still and _STYLUS and _STYLUS[0][0][0] is base and _STYLUS[0][0][1:] == key[1:]:
            return _STYLUS[0][1]
    stylus = _guarded(term, "its forward change", lambda: kinematics.stylus_jacobians(
        samples.arm, params, samples.q, FRAME, samples, tool=samples.tool, adjust=change,
        tilts=bool(key[3])))
    if still:
        with _LOCK:
            _STYLUS[:] = [(key, stylus)]
    return stylus


def _unchanged(change: Adjustment) -> bool:
    """Whether a change of the arm leaves it as it is (every field as a new one's).

    A mapping's entry that a new change lacks counts as zeros (a frame's twist, say).
    """
    try:
        fresh = Adjustment(change.n, change.n_axes)
        filled = [f.name for f in dataclasses.fields(change) if not f.init]
    except TypeError:  # built otherwise: not known to be unchanged
        return False
    for name in filled:
        now, new = getattr(change, name), getattr(fresh, name)
        if isinstance(now, dict) and isinstance(new, dict):  # an entry a new one lacks: zeros
            same = all(isinstance(a, np.ndarray) and not np.any(a != new.get(k, 0.0))
                       for k, a in now.items())
        else:
            same = isinstance(now, np.ndarray) and isinstance(new, np.ndarray) \
                and np.array_equal(now, new)
        if not same:
            return False
    return True


def disagreement(column: np.ndarray, points: Sequence[np.ndarray], h: float) -> str | None:
    """Return why one parameter's column differs from the central differences, or None.

    Args:
        column: the term's column of the parameter, shape (n, 3), m per unit.
        points: the modelled points at values -2h, -h, +h, +2h of the parameter, each (n, 3), m.
        h: the step, in the parameter's unit.
    """
    minus2, minus1, plus1, plus2 = points
    d1 = (plus1 - minus1) / (2 * h)
    d2 = (plus2 - minus2) / (4 * h)
    derivative = (4 * d1 - d2) / 3
    size = max(float(np.abs(p).max()) for p in points)
    ulp = ROUNDING_ULPS * np.finfo(float).eps
    tol = float(np.abs(d2 - d1).max()) + 1.5 * ulp * size / h + ulp * float(np.abs(column).max())
    off = float(np.abs(column - derivative).max())
    if off <= tol:
        return None
    return (f"columns up to {np.abs(column).max():.3g}, central differences up to "
            f"{np.abs(derivative).max():.3g} (m per unit), apart by {off:.3g} > {tol:.2g}")


def _points(term: Term, params: Parameters, samples: Samples, values: np.ndarray,
            step: np.ndarray) -> list[np.ndarray]:
    """Return the modelled points at the term's values moved by -2, -1, 1 and 2 times ``step``.

    Each (n, 3), m, in the MT-CS: the stylus centres with the term's change of the arm alone, plus
    its change of the measured point. The four in one call of the kinematics (the samples
    repeated) where their adjustments stack, else one call each.
    """
    moved = [values + t * step for t in (-2.0, -1.0, 1.0, 2.0)]
    changes = [_guarded(term, "its forward change", functools.partial(_adjustment, term, v, samples))
               for v in moved]
    shifts = [_guarded(term, "its forward change", functools.partial(term.shift, v, samples))
              for v in moved]
    arm, n, stacked = samples.arm, samples.n, _stacked(changes)
    if stacked is None:
        pos = [_guarded(term, "its forward change", functools.partial(
            kinematics.stylus_positions, arm, params, samples.q, FRAME, samples, tool=samples.tool,
            adjust=change)) for change in changes]
    else:
        tools = kinematics.tool_rows(arm, n, None, samples)
        every = _guarded(term, "its forward change", functools.partial(
            kinematics.stylus_positions, arm, params, np.tile(samples.q, (len(moved), 1)), FRAME,
            tool=np.tile(tools, len(moved)), adjust=stacked))
        pos = [every[i * n:(i + 1) * n] for i in range(len(moved))]
    return [p if shift is None else p + np.asarray(shift, dtype=float)
            for p, shift in zip(pos, shifts)]


def _adjustment(term: Term, values: np.ndarray, samples: Samples) -> Adjustment:
    """Return the term's change of the arm alone at these values."""
    out = Adjustment(samples.n, samples.arm.n_axes)
    term.adjust(values, samples, out)
    return out


def _stacked(parts: list[Adjustment]) -> Adjustment | None:
    """Return the changes of the arm one after the other (samples repeated), or None.

    Generic in what an :class:`Adjustment` holds: every field it fills itself is an array with a
    row per sample, or a mapping of such arrays (an entry one change lacks: zeros); otherwise
    (None) the kinematics take each change apart.
    """
    n = parts[0].n
    try:
        out = Adjustment(n * len(parts), parts[0].n_axes)
        filled = [f.name for f in dataclasses.fields(out) if not f.init]
    except TypeError:  # built otherwise: taken apart
        return None
    for name in filled:
        fields = [getattr(p, name) for p in parts]
        if all(isinstance(f, dict) for f in fields):
            if (merged := _stacked_entries(fields, n)) is None:
                return None
            setattr(out, name, merged)
        elif all(_per_sample(f, n) for f in fields):
            setattr(out, name, np.concatenate(fields))
        else:
            return None
    return out


def _stacked_entries(fields: list[dict[Any, Any]], n: int) -> dict[Any, np.ndarray] | None:
    """Return mappings of per-sample arrays stacked by key (zeros where one lacks a key), or None."""
    keys = list(dict.fromkeys(k for f in fields for k in f))
    out = {}
    for key in keys:
        have = [f[key] for f in fields if key in f]
        if not all(_per_sample(a, n) for a in have):
            return None
        out[key] = np.concatenate([f.get(key, np.zeros_like(have[0])) for f in fields])
    return out


def _per_sample(value: Any, n: int) -> bool:
    """Whether a value is an array with a row per sample (n rows)."""
    return isinstance(value, np.ndarray) and value.ndim > 0 and value.shape[0] == n


def _guarded(term: Term, what: str, run: Callable[[], T]) -> T:
    """Return ``run()``; a plugin's exception (not the package's own) named in one line."""
    try:
        out = run()
    except AacmmError:
        raise
    except Exception as exc:  # noqa: BLE001 - a plugin's code: named, in one line
        raise PluginOutputError(term, f"{what} raised {type(exc).__name__}: {exc}") from None
    return out
