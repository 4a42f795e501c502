"""The CSV reader's memory and its typed columns (issue 41): a campaign file's cells are kept as
8-byte numbers, never as Python objects, and the rows that repeat an earlier row are found as the
cell-by-cell comparison finds them."""

from __future__ import annotations

import tracemalloc
from array import array
from pathlib import Path

import numpy as np
import pytest

from aacmm_pin.data import campaign as cp
from aacmm_pin.data.csv_table import CHUNK_ROWS, Table, read_table
from aacmm_pin.errors import Problem

HEADER = "location,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg,dx_mm,dy_mm,dz_mm\n"


def _spat(path: Path, rows: int, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    cells = np.column_stack([rng.integers(1, 5, rows), rng.uniform(-170, 170, (rows, 7)),
                             rng.normal(0, 0.01, (rows, 3))])
    with path.open("w") as f:
        f.write(HEADER)
        np.savetxt(f, cells, fmt=["%d"] + ["%.9f"] * 10, delimiter=",")
    return path


def _read(path: Path, problems: list[Problem]) -> Table | None:
    return read_table(path, *cp._FILES["spat.csv"], problems, extras="numbers")


def test_a_clean_file_is_kept_in_typed_columns_near_its_own_size(tmp_path: Path) -> None:
    """Peak memory of reading: the file's bytes and its text (each the file's size, both held
    while the one is decoded into the other), the columns (8 bytes a cell) and one chunk's cells
    as Python objects (under 128 bytes a cell); not a Python float (24 bytes) and a list slot (8)
    per cell kept, nor StringIO's copy of the text at 4 bytes a character (the reader before
    peaked at 2.4x this bound on this file, this one at 0.72x)."""
    path = _spat(tmp_path / "spat.csv", 20_000)
    size = path.stat().st_size
    problems: list[Problem] = []
    tracemalloc.start()
    try:
        table = _read(path, problems)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert problems == [] and table is not None and len(table.lines) == 20_000
    assert isinstance(table.lines, array)
    assert all(isinstance(c, array) for c in table.cols.values())
    columns = 8 * 12 * 20_000  # 11 columns and the lines
    chunk = CHUNK_ROWS * 11 * 128
    assert peak < 2 * size + columns + chunk, (peak, size, columns, chunk)


@pytest.mark.parametrize("bad_row", [5, CHUNK_ROWS + 7])
def test_a_bad_cell_gives_lists_with_none_as_before(tmp_path: Path, bad_row: int) -> None:
    """One bad cell, in the first chunk or a later one: its problem, and the columns as the
    cell-by-cell reading gives them (None at the bad cell, the other values as read)."""
    path = _spat(tmp_path / "spat.csv", CHUNK_ROWS + 20)
    lines = path.read_text().splitlines()
    cells = lines[bad_row].split(",")
    good = float(cells[2])
    cells[2] = "abc"
    lines[bad_row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    problems: list[Problem] = []
    table = _read(path, problems)
    assert table is not None and len(problems) == 1
    assert problems[0].line == bad_row + 1 and problems[0].column == "q2_deg"
    q2 = table.cols["q2_deg"]
    assert isinstance(q2, list) and q2[bad_row - 1] is None and None not in q2[:bad_row - 1]
    assert isinstance(table.cols["location"][0], int) and good not in q2


def _copies_by_hand(cols: list[list[object]]) -> tuple[int, int, int, int] | None:
    """(first copy, the row it repeats, copies, most copies of one row) by a dict of rows."""
    seen: dict[tuple[object, ...], int] = {}
    count: dict[int, int] = {}
    copies = []
    for r, row in enumerate(zip(*cols)):
        key = tuple(v + 0.0 if isinstance(v, float) else v for v in row)
        first = seen.setdefault(key, r)
        count[first] = count.get(first, 0) + 1
        if first != r:
            copies.append((r, first))
    if not copies:
        return None
    return copies[0][0], copies[0][1], len(copies), max(count.values())


def test_repeated_rows_as_a_row_by_row_comparison_finds_them() -> None:
    rng = np.random.default_rng(1)
    for trial in range(200):
        n = int(rng.integers(2, 50))
        values = rng.integers(0, 3, (n, 2)).astype(float)
        values[rng.random((n, 2)) < 0.2] *= -0.0  # -0.0 equals 0.0
        cols: list[list[object]] = [rng.integers(1, 3, n).tolist(), values[:, 0].tolist(),
                                    values[:, 1].tolist()]
        if trial % 2:
            cols.append([str(v) for v in rng.integers(0, 2, n)])
        typed = [array("q", cols[0]), array("d", cols[1]), cols[2], *cols[3:]]
        found = cp._repeated_rows(typed)
        got = None if found is None else (int(found[0][0]), int(found[1][0]), found[0].size,
                                          found[2])
        assert got == _copies_by_hand(cols)
