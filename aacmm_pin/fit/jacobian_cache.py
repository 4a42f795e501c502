"""The last data Jacobian built in the process, kept for the next call at the same point.

A campaign's Jacobian can weigh hundreds of MB, and the fit asks for it at one point several times
(the solver's last step, the decision at the solution, the covariance, the analyses after it): one
is kept, the newest, whatever layout it is of; it is released before the next one is built, so
that two never share the peak, and it goes with its layout (held by a weak reference: a fit's
Jacobian is freed when its layout is). :data:`LAST_JACOBIAN` is the process' one
(:meth:`aacmm_pin.fit.unknowns.Unknowns.jacobian` goes through it).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import Any, Generic, NamedTuple, TypeVar, cast

import numpy as np

T = TypeVar("T")


class _Held(NamedTuple):
    owner: weakref.ref[Any]
    """The layout the Jacobian is of (a weak reference, compared by the object's identity)."""
    key: bytes
    """The point's bytes."""
    q: np.ndarray
    """The readouts it was built for (by identity: the same array)."""
    result: Any
    """What was built."""


class JacobianCache(Generic[T]):
    """One slot: the last result of ``build(x, q)`` with its layout, point and readouts."""

    def __init__(self) -> None:
        self._held: _Held | None = None

    def get(self, owner: object, x: np.ndarray, q: np.ndarray,
            build: Callable[[np.ndarray, np.ndarray], T]) -> T:
        """Return ``build(x, q)`` of ``owner``: the kept one if it is for the same, else built.

        The kept one is released before another is built (its memory is free for the new one).
        """
        key = x.tobytes()
        held = self._held  # read once: other threads may replace it
        if held is not None and held.owner() is owner and held.key == key and held.q is q:
            return cast(T, held.result)
        del held
        self._held = None
        result = build(x, q)
        self._held = _Held(weakref.ref(owner, self._drop), key, q, result)  # q: by identity
        return result

    def _drop(self, ref: weakref.ref[Any]) -> None:
        """Release the kept result when its layout is gone (a weak reference's callback)."""
        held = self._held
        if held is not None and held.owner is ref:
            self._held = None

    def clear(self) -> None:
        """Release the kept result."""
        self._held = None


LAST_JACOBIAN: JacobianCache[object] = JacobianCache()
"""The process' kept Jacobian (only one is kept in a process: the newest)."""
