r"""The R-Test nest: the sensor directions that turn three gauge readings into a displacement.

Gauge k touches the stylus sphere along the unit vector :math:`u_k` (in the MT-CS, pointing the
way the sphere centre moves to *increase* the reading). For displacements much smaller than the
sphere (um against mm) the reading is the projection of the sphere-centre displacement ``d`` on
that direction, :math:`g_k = u_k \cdot d` (the neglected term is :math:`|d|^2 / 2R`, 1e-5 um for
15 um on a 10 mm sphere), so :math:`d = U^{-1} g` with the rows of ``U`` the three directions.

A nest file is JSON with three direction vectors (normalised when read; orthogonal x, y, z is the
default nest)::

    {"directions": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aacmm_pin.data.json_file import read_json
from aacmm_pin.data.problem_log import key_problems
from aacmm_pin.errors import FileFormatError, Problem

MIN_DETERMINANT = 0.1
"""Smallest ``|det U|`` accepted: three unit directions closer to a plane cannot resolve 3D."""


@dataclass(frozen=True, eq=False)
class Nest:
    """Sensor directions of an R-Test nest."""

    directions: np.ndarray = field(default_factory=lambda: np.eye(3))
    """Unit direction of gauges 1, 2, 3 in the MT-CS, one per row, shape (3, 3)."""
    _inverse: np.ndarray = field(init=False, repr=False)
    """Inverse of ``directions``, shape (3, 3)."""

    def __post_init__(self) -> None:
        u = np.array(self.directions, dtype=float)
        if u.shape != (3, 3) or not np.isfinite(u).all():
            raise ValueError(f"directions: three finite 3-vectors expected, got shape {u.shape}")
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        if abs(np.linalg.det(u)) < MIN_DETERMINANT:
            raise ValueError(f"directions: nearly coplanar (|det| = {abs(np.linalg.det(u)):.3g} < "
                             f"{MIN_DETERMINANT}); three independent directions are needed")
        u.setflags(write=False)
        object.__setattr__(self, "directions", u)
        inverse = np.linalg.inv(u)
        inverse.setflags(write=False)
        object.__setattr__(self, "_inverse", inverse)

    def displacement(self, readings: np.ndarray) -> np.ndarray:
        """Return the sphere displacement for gauge readings.

        Args:
            readings: readings of gauges 1-3, shape (3,) or (N, 3), in m.

        Returns:
            Displacement in the MT-CS, same shape, in m.
        """
        displacement: np.ndarray = np.asarray(readings, dtype=float) @ self._inverse.T
        return displacement

    def readings(self, displacement: np.ndarray) -> np.ndarray:
        """Return the gauge readings of a displacement, shape (3,) or (N, 3), in m (inverse)."""
        readings: np.ndarray = np.asarray(displacement, dtype=float) @ self.directions.T
        return readings


def read_nest(path: str | Path) -> Nest:
    """Read a nest file (JSON with ``directions``: three 3-vectors).

    Raises:
        FileFormatError: for unreadable JSON, missing or malformed directions, zero or coplanar
            vectors, a key other than ``directions``, each problem with the file.
    """
    path = Path(path)
    data = read_json(path, 2**20, "a nest file")  # a nest file is about 100 bytes
    raw = data.get("directions") if isinstance(data, dict) else None
    problems = key_problems(path, data, ("directions",)) if isinstance(data, dict) else []
    try:
        u = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        u = np.zeros(0)
    if u.shape != (3, 3) or not np.isfinite(u).all():
        problems.append(Problem(path, None, "directions", "three finite 3-vectors expected, e.g. "
                                                         "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]"))
    else:
        for k, norm in enumerate(np.linalg.norm(u, axis=1)):
            if norm < 1e-9:
                problems.append(Problem(path, None, "directions", f"vector {k + 1} is zero"))
    if not problems:
        try:
            return Nest(u)
        except ValueError as exc:
            problems.append(Problem(path, None, "directions", str(exc).split(": ", 1)[1]))
    raise FileFormatError(problems)
