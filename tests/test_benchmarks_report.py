"""BENCHMARKS.md's comparisons: every ratio states its spread, and the kinematics' strongest
baseline computes what aacmm_pin computes (so its time is a fair comparison)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from aacmm_pin import Parameters, load_arm, stylus_jacobians, stylus_positions
from benchmarks.kinematics import hand_jacobians, hand_positions

BENCH = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
COMPARISONS = ("kinematics", "identify", "uncertainty", "discover", "robots", "cli")
"""The sections that compare methods by a ratio (``identify-large`` and ``figures`` state shares
and targets of their own)."""
RATIO = re.compile(r"^(\d+(?:\.\d+)?)x\b(.*)$")


def section(name: str) -> str:
    """The text of one section of BENCHMARKS.md."""
    found = re.search(rf"<!-- {re.escape(name)} -->(.*?)<!-- /{re.escape(name)} -->",
                      BENCH.read_text(), flags=re.S)
    assert found is not None, f"BENCHMARKS.md has no section {name}"
    return found.group(1)


def ratio_cells(text: str) -> list[str]:
    """The table cells of ``text`` that state a ratio ("1.6x ...")."""
    cells = [c.strip() for line in text.splitlines() if line.startswith("|")
             for c in line.strip("|").split("|")]
    return [c for c in cells if RATIO.match(c)]


@pytest.mark.parametrize("name", COMPARISONS)
def test_every_ratio_states_its_range(name: str) -> None:
    """A ratio in a table is followed by its range over the rounds, "(lo - hi)", with lo <= hi;
    a lone "1x" marks the reference row."""
    cells = ratio_cells(section(name))
    assert cells, f"section {name} states no ratio"
    for cell in cells:
        value, rest = RATIO.match(cell).groups()  # type: ignore[union-attr]
        if float(value) == 1.0 and not rest.strip():
            continue  # the reference row
        spread = re.match(r"\s*\((\d+(?:\.\d+)?) - (\d+(?:\.\d+)?)\)", rest)
        assert spread is not None, f"{name}: ratio without its range: {cell!r}"
        assert float(spread.group(1)) <= float(spread.group(2)), cell


def test_handwritten_chain_is_the_same_model() -> None:
    """The kinematics' strongest baseline (hand-written numpy, vectorised) gives aacmm_pin's
    positions and all 38 Jacobian columns at perturbed parameters, to rounding (1e-12 m, m/rad)."""
    arm = load_arm()
    rng = np.random.default_rng(3)
    nominal = Parameters.nominal(arm)
    params = nominal.replace(rotation_abc=rng.normal(0, 0.01, 3),
                             translation=rng.normal(0, 0.1, 3),
                             dh={k: rng.normal(0, 1e-3) for k in nominal.dh},
                             tool=nominal.tool + rng.normal(0, 0.01, 3))
    q = rng.uniform(-3, 3, (50, 7))
    ours = stylus_jacobians(arm, params, q)
    hand_p, hand_j = hand_jacobians(q, params)
    blocks = np.concatenate([ours.rotation, ours.translation, ours.angles, ours.dh, ours.tool],
                            axis=2)
    assert np.abs(ours.position - hand_p).max() < 1e-12
    assert np.abs(blocks - hand_j).max() < 1e-12
    assert np.abs(stylus_positions(arm, params, q) - hand_positions(q, params)).max() < 1e-12
