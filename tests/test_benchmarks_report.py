"""BENCHMARKS.md's comparisons: every ratio states its spread (pooled over the earlier runs of the
same code), and the kinematics' strongest baseline computes what aacmm_pin computes (so its time
is a fair comparison)."""

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
    """A ratio in a table is followed by its range over the rounds (of its run and the earlier
    runs the section names), "(lo - hi)", with lo <= the ratio <= hi (a ratio of medians lies
    within the range of the paired rounds' ratios); a lone "1x" marks the reference row."""
    cells = ratio_cells(section(name))
    assert cells, f"section {name} states no ratio"
    for cell in cells:
        value, rest = RATIO.match(cell).groups()  # type: ignore[union-attr]
        if float(value) == 1.0 and not rest.strip():
            continue  # the reference row
        spread = re.match(r"\s*\((\d+(?:\.\d+)?) - (\d+(?:\.\d+)?)\)", rest)
        assert spread is not None, f"{name}: ratio without its range: {cell!r}"
        assert float(spread.group(1)) <= float(value) <= float(spread.group(2)), cell


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
    ours = stylus_jacobians(arm, params, q, frame="mt")
    hand_p, hand_j = hand_jacobians(q, params)
    blocks = np.concatenate([ours.rotation, ours.translation, ours.angles, ours.dh, ours.tool],
                            axis=2)
    assert np.abs(ours.position - hand_p).max() < 1e-12
    assert np.abs(blocks - hand_j).max() < 1e-12
    assert np.abs(stylus_positions(arm, params, q) - hand_positions(q, params)).max() < 1e-12



@pytest.fixture
def report(tmp_path, monkeypatch):
    """benchmarks._report writing to a temporary BENCHMARKS.md and history, as ``bench.py --flag``."""
    from benchmarks import _report

    monkeypatch.setattr(_report, "BENCH", tmp_path / "BENCHMARKS.md")
    monkeypatch.setattr(_report, "HISTORY", tmp_path / "history.json")
    monkeypatch.setattr(_report, "_code", lambda: "code-a")
    monkeypatch.setattr("sys.argv", ["bench.py", "--flag", "value"])
    monkeypatch.setattr(_report, "_THIS_RUN", {})
    return _report


def _run(report, per_round: list[float], name: str = "a / b") -> tuple[str, str]:
    """One run of a script stating one ratio (``per_round`` over ones); its cell and section."""
    cell = report.ratio(per_round, np.ones(len(per_round)), name=name)
    report.write_section("bench", f"| a | {cell} |")
    return cell, section_of(report.BENCH.read_text(), "bench")


def section_of(text: str, name: str) -> str:
    found = re.search(rf"<!-- {name} -->(.*?)<!-- /{name} -->", text, flags=re.S)
    assert found is not None
    return found.group(1)


def test_a_ratio_range_pools_the_earlier_runs_of_the_same_code(report, capsys) -> None:
    """The first run states its own rounds' range; a second run of the same code on the same
    machine states the range over both runs' rounds, its own median as the value, and names the
    value that fell outside the first run's range."""
    cell, text = _run(report, [2.0, 2.1, 2.2])
    assert cell == "2.10x (2.00 - 2.20)"
    assert "no earlier run" in text
    cell, text = _run(report, [2.4, 2.5, 2.6])
    assert cell == "2.50x (2.00 - 2.60)"
    assert "0 of 1 fell within the earlier run's range, not: a / b: 2.50x against 2.00 - 2.20" in text
    assert "NOT reproduced" in capsys.readouterr().err
    cell, text = _run(report, [2.3, 2.3, 2.3])
    assert cell == "2.30x (2.00 - 2.60)"
    assert "the one value fell within the earlier runs' range" in text


def test_ratios_are_pooled_by_name(report) -> None:
    """A run that states fewer ratios, or others, pools each with the earlier rounds of its own
    name only."""
    report.ratio([3.0], [1.0], name="first")
    report.ratio([7.0], [1.0], name="second")
    report.write_section("bench", "two ratios")
    assert report.ratio([7.5], [1.0], name="second") == "7.50x (7.00 - 7.50)"
    assert report.ratio([1.0], [1.0], name="new") == "1.00x (1.00 - 1.00)"
    with pytest.raises(ValueError, match="stated twice"):
        report.ratio([1.0], [1.0], name="new")


def test_other_code_or_arguments_start_a_new_history(report, monkeypatch) -> None:
    """Rounds of another code digest or of the script with other arguments are not pooled; the
    history keeps the latest KEEP runs of a key, drops the script's runs of older code on this
    machine and keeps every other script's runs."""
    import json

    _run(report, [5.0, 5.0])
    monkeypatch.setattr("sys.argv", ["other.py"])
    _run(report, [9.0, 9.0])
    monkeypatch.setattr("sys.argv", ["bench.py", "--flag", "value"])
    monkeypatch.setattr(report, "_code", lambda: "code-b")
    assert _run(report, [2.0, 2.0])[0] == "2.00x (2.00 - 2.00)"  # old code's 5.0 not pooled
    monkeypatch.setattr("sys.argv", ["bench.py", "--flag", "other value"])
    assert _run(report, [3.0, 3.0])[0] == "3.00x (3.00 - 3.00)"
    monkeypatch.setattr("sys.argv", ["bench.py"])
    for v in range(report.KEEP + 2):
        cell, _ = _run(report, [10.0 + v, 10.0 + v])
    last = 10.0 + report.KEEP + 1
    assert cell == f"{last:.0f}x ({last - report.KEEP + 1:.0f} - {last:.0f})"  # the latest KEEP
    runs = json.loads(report.HISTORY.read_text())
    scripts = [r["script"] for r in runs]
    assert scripts.count("bench") == report.KEEP
    assert scripts.count("other") == 1
    assert [r["code"] for r in runs if r["script"] == "bench --flag value"] == ["code-b"]


def test_an_unreadable_history_is_reported_and_replaced(report, capsys) -> None:
    """A malformed history (e.g. a merge conflict) does not stop a run after its timing: it is
    named on stderr, read as empty, and a readable one is written."""
    import json

    report.HISTORY.write_text("<<<<<<< HEAD\n[]\n")
    cell, text = _run(report, [2.0, 2.0])
    assert cell == "2.00x (2.00 - 2.00)" and "no earlier run" in text
    assert "unreadable" in capsys.readouterr().err
    assert len(json.loads(report.HISTORY.read_text())) == 1


def test_the_code_digest_follows_the_script_and_what_it_names(tmp_path, monkeypatch) -> None:
    """The digest is that of the package, the script and the benchmark modules it names: it
    changes when one of them changes, not when another benchmark does."""
    from benchmarks import _report

    root = tmp_path / "repo"
    (root / "aacmm_pin").mkdir(parents=True)
    (root / "benchmarks").mkdir()
    (root / "tests").mkdir()
    (root / "aacmm_pin" / "core.py").write_text("x = 1\n")
    (root / "benchmarks" / "base.py").write_text("y = 1\n")
    (root / "benchmarks" / "unrelated.py").write_text("z = 1\n")
    script = root / "benchmarks" / "bench.py"
    script.write_text("from benchmarks.base import y\n")
    monkeypatch.setattr(_report, "BENCH", root / "BENCHMARKS.md")
    monkeypatch.setattr("sys.argv", [str(script)])

    def digest() -> str:
        _report._code.cache_clear()
        return _report._code()

    first = digest()
    assert digest() == first
    (root / "benchmarks" / "unrelated.py").write_text("z = 2\n")
    assert digest() == first
    for changed in (root / "benchmarks" / "base.py", root / "aacmm_pin" / "core.py", script):
        changed.write_text(changed.read_text() + "# changed\n")
        assert digest() != first
        first = digest()
    _report._code.cache_clear()
