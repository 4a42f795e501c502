"""The extension terms' forward change: how terms with their values change the arm and the point.

The model arithmetic of the effect library (the registry only registers and looks up): a
calibration's terms with their values (:meth:`aacmm_pin.model.parameters.Parameters.term_values`,
looked up once where the parameters were made) give the change of the arm at some samples
(:class:`~aacmm_pin.model.kinematics.Adjustment`, applied by :mod:`aacmm_pin.model.kinematics`)
and of the measured point (:func:`measurement_shift`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from aacmm_pin.effects.base import Adjustment, Term
from aacmm_pin.errors import AacmmError
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples


def term_values(params: Parameters) -> list[tuple[Term, np.ndarray]]:
    """Return the parameters' extension terms with their values (k,) each, SI, in key order.

    Raises:
        EffectNotFound: for a key no registered effect knows (the registry's error).
    """
    out = []
    for term, values in params.term_values():
        if not isinstance(term, Term):
            raise AacmmError(f"extensions: {term.key!r} holds {term!r}, not an "
                             f"aacmm_pin.effects.Term")
        out.append((term, values))
    return out


def adjustment(params: Parameters, samples: Samples, n_axes: int) -> Adjustment:
    """Return how the parameters' extension terms change the arm at the samples (:class:`Adjustment`)."""
    return terms_adjustment(term_values(params), samples, n_axes)


def terms_adjustment(terms: Iterable[tuple[Term, np.ndarray]], samples: Samples, n_axes: int
                     ) -> Adjustment:
    """Return how terms with their values change the arm at the samples (see :class:`Adjustment`)."""
    out = Adjustment(samples.n, n_axes)
    for term, values in terms:
        term.adjust(np.asarray(values, dtype=float), samples, out)
    return out


def measurement_shift(terms: Iterable[Term], extensions: Mapping[str, np.ndarray], samples: Samples
                      ) -> np.ndarray:
    """Return the terms' change of the measured point, shape (N, 3), m.

    ``extensions``: each term's values by its key (``Parameters.extensions``).
    """
    out = np.zeros((samples.n, 3))
    for t in terms:
        shift = t.shift(extensions[t.key], samples)
        if shift is not None:
            out += shift
    return out
