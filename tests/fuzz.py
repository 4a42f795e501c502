"""Seeded mutations of a campaign folder and of a calibration folder, and the verdict on each.

Used by ``test_fuzz.py``. Every mutation is a function ``(folder, rng) -> str`` that changes the
folder's files in place and returns a label (``"file: what"``). A mutation is run the way a user
runs the files: a campaign by ``read_campaign`` + ``identify(..., "dh")`` + ``validate`` (given the
calibration's accuracy, as ``aacmm-pin validate`` reads it from report.json), a
calibration by ``read_parameters`` + ``load_arm`` + ``check_against_arm`` + ``predict`` +
``validate``. The verdict (:func:`judge_campaign`, :func:`judge_calibration`) is one of

- ``refused``: an :class:`~aacmm_pin.errors.AacmmError` or ``ValueError`` with a message;
- ``same``: accepted, and the result equals the clean one within the tolerance;
- ``flagged``: accepted with a different result that the API flags (``success`` False, outliers
  or suspects, unidentifiable parameters, a :class:`~aacmm_pin.errors.CampaignWarning` of the
  reader);
- ``changed``: the user asked for something else (a plausible value changed in
  parameters.json): only "no traceback, no hang" is asserted;

and anything else (another exception, a hang, a different unflagged result) is a failure.
"""

from __future__ import annotations

import json
import shutil
import signal
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

import aacmm_pin as ap
from aacmm_pin.errors import CampaignWarning
from aacmm_pin.model.parameters import check_against_arm

CAMPAIGN_FILES = ("spat.csv", "locations.csv", "lengthbar.csv", "bar.csv", "points.csv")
"""The files a mutation picks from (those the folder holds, in this order)."""


class Hang(Exception):
    """A mutation ran past its time limit."""


@contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise :class:`Hang` in the main thread after ``seconds``."""
    def on_alarm(signum: int, frame: Any) -> None:
        raise Hang(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


# ---------------------------------------------------------------- CSV text mutations

def _rows(path: Path) -> list[list[str]]:
    return [line.split(",") for line in path.read_text().splitlines()]


def _put(path: Path, rows: list[list[str]], end: str = "\n") -> None:
    path.write_text(end.join(",".join(r) for r in rows) + end, newline="")


def _pick_file(folder: Path, rng: np.random.Generator) -> Path:
    names = [name for name in CAMPAIGN_FILES if (folder / name).is_file()] or list(CAMPAIGN_FILES)
    return folder / names[rng.integers(len(names))]


def _body_row(rows: list[list[str]], rng: np.random.Generator) -> int:
    return int(rng.integers(1, len(rows))) if len(rows) > 1 else 0


CELL_VALUES = ("abc", "nan", "NaN", "inf", "-inf", "1e308", "1e300", "", " ", "-1", "0",
               "-0.5", "1e-300", "12,5", "0x10", "1_000", "++1", "1e400", "true", "\x00", "é")


def m_crlf(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    _put(path, _rows(path), "\r\n")
    return f"{path.name}: CRLF line endings"


def m_bom(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    return f"{path.name}: UTF-8 BOM"


def m_swap_columns(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    i, j = rng.choice(len(rows[0]), 2, replace=False)
    for r in rows:
        r[i], r[j] = r[j], r[i]
    _put(path, rows)
    return f"{path.name}: columns {rows[0][j]} and {rows[0][i]} swapped (header too)"


def m_trailing_newlines(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    path.write_text(path.read_text() + "\n\n")
    return f"{path.name}: blank lines at the end"


SAME = (m_crlf, m_bom, m_swap_columns, m_trailing_newlines)
"""Campaign mutations that do not change the meaning: the result must be the clean one (or, at
worst, the file refused)."""


def m_delete_row(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    k = _body_row(rows, rng)
    del rows[k]
    _put(path, rows)
    return f"{path.name}: line {k + 1} deleted"


def m_duplicate_row(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    k = _body_row(rows, rng)
    rows.insert(k, list(rows[k]))
    _put(path, rows)
    return f"{path.name}: line {k + 1} duplicated"


def m_swap_rows(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    i, j = _body_row(rows, rng), _body_row(rows, rng)
    rows[i], rows[j] = rows[j], rows[i]
    _put(path, rows)
    return f"{path.name}: lines {i + 1} and {j + 1} swapped"


def m_delete_column(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    j = int(rng.integers(len(rows[0])))
    name = rows[0][j]
    for r in rows:
        del r[j]
    _put(path, rows)
    return f"{path.name}: column {name} deleted"


def m_duplicate_column(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    j = int(rng.integers(len(rows[0])))
    for r in rows:
        r.append(r[j])
    _put(path, rows)
    return f"{path.name}: column {rows[0][j]} duplicated at the end"


def m_rename_header(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    j = int(rng.integers(len(rows[0])))
    old = rows[0][j]
    new = [old.upper(), old + "x", old.replace("_mm", "_m").replace("_deg", "_rad"),
           " " + old, "q9_deg", "q1_deg", "", "location"][int(rng.integers(8))]
    rows[0][j] = new
    _put(path, rows)
    return f"{path.name}: header {old!r} renamed {new!r}"


def m_cell(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    k = _body_row(rows, rng)
    j = int(rng.integers(len(rows[k])))
    value = CELL_VALUES[int(rng.integers(len(CELL_VALUES)))]
    if value == "-1" and rng.random() < 0.5 and rows[k][j]:
        value = rows[k][j][1:] if rows[k][j].startswith("-") else "-" + rows[k][j]
    old, rows[k][j] = rows[k][j], value
    _put(path, rows)
    return f"{path.name}: line {k + 1} column {j + 1} {old!r} -> {value!r}"


def m_huge_cell(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    k = _body_row(rows, rng)
    j = int(rng.integers(len(rows[k])))
    factor = [1e3, 1e6, 1e9, -1e3, 1e-3][int(rng.integers(5))]
    try:
        rows[k][j] = repr(float(rows[k][j]) * factor)
    except ValueError:
        rows[k][j] = rows[k][j] * 50
    _put(path, rows)
    return f"{path.name}: line {k + 1} column {j + 1} times {factor:g}"


def m_scale_column(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    j = int(rng.integers(len(rows[0])))
    # unit errors: deg <-> rad for angles, mm <-> m or inch for lengths, any of them elsewhere
    angles, lengths = [np.pi / 180, 180 / np.pi], [1e-3, 1e3, 25.4, 1 / 25.4]
    factors = (angles if rows[0][j].endswith("_deg") else
               lengths if rows[0][j].endswith("_mm") else angles + lengths)
    factor = factors[int(rng.integers(len(factors)))]
    return scale_column(path, j, factor)


def scale_column(path: Path, j: int, factor: float) -> str:
    """Multiply every number of column ``j`` (0-based) of a CSV by ``factor``; return the label."""
    rows = _rows(path)
    for r in rows[1:]:
        try:
            r[j] = repr(float(r[j]) * factor)
        except (ValueError, IndexError):
            pass
    _put(path, rows)
    return f"{path.name}: column {rows[0][j]} times {factor:.6g}"


def m_truncate(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    data = path.read_bytes()
    n = int(rng.integers(len(data)))
    path.write_bytes(data[:n])
    return f"{path.name}: truncated to {n} of {len(data)} bytes"


def m_garbage(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    data = path.read_bytes()
    n = int(rng.integers(len(data) + 1))
    junk = rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8).tobytes()
    path.write_bytes(data[:n] + junk + data[n:])
    return f"{path.name}: {len(junk)} random bytes at byte {n}"


def m_binary_file(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    path.write_bytes(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    return f"{path.name}: replaced by binary garbage"


def m_extra_separator(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    k = int(rng.integers(len(rows)))
    j = int(rng.integers(len(rows[k]) + 1))
    rows[k].insert(j, "")
    _put(path, rows)
    return f"{path.name}: extra separator in line {k + 1} at cell {j + 1}"


def m_other_separator(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    sep = [";", "\t", " "][int(rng.integers(3))]
    path.write_text(path.read_text().replace(",", sep))
    return f"{path.name}: separator {sep!r}"


def m_delete_file(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    path.unlink()
    return f"{path.name}: deleted"


def m_empty_file(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    path.write_bytes(b"" if rng.random() < 0.5 else path.read_text().splitlines()[0].encode())
    return f"{path.name}: emptied (or header only)"


def m_file_to_folder(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    path.unlink()
    path.mkdir()
    return f"{path.name}: a folder"


def m_swap_cells_in_row(folder: Path, rng: np.random.Generator) -> str:
    path = _pick_file(folder, rng)
    rows = _rows(path)
    k = _body_row(rows, rng)
    if len(rows[k]) < 2:
        return f"{path.name}: nothing swapped"
    i, j = rng.choice(len(rows[k]), 2, replace=False)
    rows[k][i], rows[k][j] = rows[k][j], rows[k][i]
    _put(path, rows)
    return f"{path.name}: line {k + 1} cells {i + 1} and {j + 1} swapped"


OTHER = (m_delete_row, m_duplicate_row, m_swap_rows, m_delete_column, m_duplicate_column,
         m_rename_header, m_cell, m_huge_cell, m_scale_column, m_truncate, m_garbage,
         m_binary_file, m_extra_separator, m_other_separator, m_delete_file, m_empty_file,
         m_file_to_folder, m_swap_cells_in_row)
"""Campaign mutations that may change the meaning: refused, the clean result, or flagged."""


# ---------------------------------------------------------------- points.csv mutations

def _point_columns(rows: list[list[str]]) -> list[int]:
    return [rows[0].index(c) for c in ("x_mm", "y_mm", "z_mm")]


def p_shift_tail(folder: Path, rng: np.random.Generator) -> str:
    """A bumped tracker: the last 10-50 % of the points moved by 0.2-2 mm along one direction."""
    path = folder / "points.csv"
    rows = _rows(path)
    share, shift = float(rng.uniform(0.1, 0.5)), float(rng.uniform(0.2, 2.0))
    direction = rng.normal(size=3)
    direction *= shift / np.linalg.norm(direction)
    first = int(len(rows) * (1 - share))
    for r in rows[max(first, 1):]:
        for k, d in zip(_point_columns(rows), direction):
            r[k] = repr(float(r[k]) + float(d))
    _put(path, rows)
    return f"points.csv: lines {first + 1}.. moved {shift:.2f} mm"


def p_gross_point(folder: Path, rng: np.random.Generator) -> str:
    """One point off by 0.5-5 mm (a tracker reflector knocked, a wrong pose logged)."""
    path = folder / "points.csv"
    rows = _rows(path)
    k = _body_row(rows, rng)
    size = float(rng.uniform(0.5, 5.0))
    for j, d in zip(_point_columns(rows), rng.normal(size=3)):
        rows[k][j] = repr(float(rows[k][j]) + float(size * d / np.sqrt(3)))
    _put(path, rows)
    return f"points.csv: line {k + 1} off by about {size:.1f} mm"


def p_relabel(folder: Path, rng: np.random.Generator) -> str:
    """One row's tool or group exchanged for another one of the file (a wrong label)."""
    path = folder / "points.csv"
    rows = _rows(path)
    names = [c for c in ("tool", "group") if c in rows[0]]
    if not names:
        return "points.csv: no label to change"
    j = rows[0].index(names[int(rng.integers(len(names)))])
    values = sorted({r[j] for r in rows[1:]})
    k = _body_row(rows, rng)
    others = [v for v in values if v != rows[k][j]]
    if not others:
        return "points.csv: one label only"
    old, rows[k][j] = rows[k][j], others[int(rng.integers(len(others)))]
    _put(path, rows)
    return f"points.csv: line {k + 1} {rows[0][j]} {old} -> {rows[k][j]}"


POINTS_OTHER = (p_relabel,)
"""points.csv mutations that change the meaning: refused, within the noise, or flagged."""
POINTS_NOISE = (p_shift_tail, p_gross_point)
"""points.csv mutations only a fit judged against its stated noise can flag (issue 24 item 1):
plausible cells, a residual far beyond the noise."""


# ---------------------------------------------------------------- the verdicts

CAMPAIGN_TOL = 3e-6
"""Largest change of a bar error accepted as "the clean result", m (the small campaign's bar
errors come from a fit with 2 um R-Test noise; one sample more or less moves them < 1 um)."""


def bar_errors(result: ap.ValidationResult) -> dict[tuple[int, str, str], float]:
    """Return the length errors by (placement, socket, socket) (sockets sorted), measured ones."""
    return {(k, *sorted((a, b))): float(e) for k, row in zip(result.placements, result.errors)
            for (a, b), e in zip(result.pairs, row) if np.isfinite(e)}  # A-B is B-A


def run_campaign(folder: Path, arm: ap.Arm) -> tuple[ap.Calibration, ap.ValidationResult]:
    """Run the user's path on a campaign folder: read, identify (DH), validate on its bar."""
    campaign = ap.read_campaign(folder, arm=arm)
    cal = ap.identify(campaign, arm, "dh")
    return cal, ap.validate(arm, cal.parameters, campaign, cal.accuracy)


def _refused(exc: BaseException) -> bool:
    return isinstance(exc, (ap.AacmmError, ValueError)) and bool(str(exc).strip())


def attempt(run: Callable[[], Any], seconds: float, notes: list[str] | None = None
            ) -> tuple[Any, tuple[str, str] | None]:
    """Return ``(run(), None)``, or ``(None, verdict)`` for a refusal, an exception or a hang.

    ``notes``: where the campaign warnings the run emits are added (a flag the user sees).
    """
    try:
        with time_limit(seconds), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CampaignWarning)
            out = run()
        if notes is not None:
            notes += [str(w.message) for w in caught if issubclass(w.category, CampaignWarning)]
        return out, None
    except Hang as exc:
        return None, ("FAIL", f"hang: {exc}")
    except Exception as exc:  # noqa: BLE001 - the verdict names every other exception
        if _refused(exc):
            return None, ("refused", str(exc).splitlines()[-1][:200])
        return None, ("FAIL", f"{type(exc).__name__}: {exc}")


def mutate(clean: Path, folder: Path, rng: np.random.Generator,
           other: tuple[Mutation, ...]) -> tuple[bool, list[str]]:
    """Copy the folder ``clean`` to ``folder`` and mutate it; return (kept the meaning, labels).

    15 % of the time one mutation of :data:`SAME`, else one of ``other``, sometimes (20 %) two.
    """
    same = rng.random() < 0.15
    pool = SAME if same else other
    copy_folder(clean, folder)
    labels = [pool[int(rng.integers(len(pool)))](folder, rng)]
    if not same and rng.random() < 0.2:  # sometimes two at once
        try:
            labels.append(pool[int(rng.integers(len(pool)))](folder, rng))
        except (OSError, IndexError, UnicodeDecodeError, ValueError):
            pass  # the first mutation left nothing to mutate (a file deleted, binary)
    return same, labels


def judge_campaign(folder: Path, arm: ap.Arm, clean: dict[Any, float], must_match: bool,
                   clean_unidentifiable: list[str], seconds: float = 30.0) -> tuple[str, str]:
    """Return (verdict, detail) for a mutated campaign folder; verdict "FAIL" on a failure.

    ``clean_unidentifiable`` is the clean fit's list: a different list is a flag.
    """
    notes: list[str] = []
    out, verdict = attempt(lambda: run_campaign(folder, arm), seconds, notes)
    if verdict:
        return verdict
    cal, result = out
    errors = bar_errors(result)
    # rows removed (a truncated file) leave fewer pairs measured: each one reported must agree
    same = bool(errors) and errors.keys() <= clean.keys() and all(
        abs(errors[k] - clean[k]) <= CAMPAIGN_TOL for k in errors)
    if same:
        return "same", ""
    diff = (max(abs(errors[k] - clean[k]) for k in errors) if errors and errors.keys() <= clean.keys()
            else float("nan"))
    detail = f"bar errors differ (max {diff * 1e6:.3g} um; pairs {len(errors)} vs {len(clean)})"
    if must_match:
        return "FAIL", detail + " for a mutation that keeps the meaning"
    if (not cal.success or cal.outliers or cal.suspects or result.warnings or notes
            or cal.unidentifiable != clean_unidentifiable):
        return "flagged", detail
    return "FAIL", detail + ", accepted without a flag"


POINTS_TOL_SIGMAS = 5.0
"""Largest change of a predicted point accepted as "the clean result", in standard deviations of
a prediction: a fit of p parameters to m coordinates of noise sigma predicts a new pose to about
sigma sqrt(p / (m - p)) per coordinate (the mean leverage); the largest of 30 poses' 3-D
distances is about 3 sqrt(3) of these. A mutation that leaves fewer rows has the larger one."""


def points_tolerance(cal: ap.Calibration, sigma: float) -> float:
    """Return the change of predicted points that a fit's own noise explains, m."""
    p = int(np.count_nonzero(cal.identifiable))
    return POINTS_TOL_SIGMAS * sigma * float(np.sqrt(p / max(cal.fun.size - p, 1)))


def aligned_change(a: np.ndarray, b: np.ndarray) -> float:
    """Return the largest distance between points ``b`` and ``a`` after the best rigid motion of
    ``b`` onto ``a`` (a points fit fixes the arm up to its base frame: the gauge), m."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((b - cb).T @ (a - ca))
    d = np.sign(np.linalg.det(u @ vt))
    rot = (u @ np.diag([1.0, 1.0, d]) @ vt).T
    return float(np.max(np.linalg.norm((b - cb) @ rot.T + ca - a, axis=1)))


def run_points(folder: Path, arm: ap.Arm, q_test: np.ndarray, tool_test: np.ndarray | None
               ) -> tuple[ap.Calibration, np.ndarray]:
    """Run the user's path on a points campaign: read, identify (DH), predict new poses."""
    campaign = ap.read_campaign(folder, arm=arm)
    cal = ap.identify(campaign, arm, "dh")
    return cal, ap.predict(arm, cal.parameters, q_test, tool=tool_test)


def flags(cal: ap.Calibration, clean_unidentifiable: list[str]) -> list[str]:
    """Return what a calibration flags: failure, outliers, suspects, other unidentifiables."""
    out = [] if cal.success else [f"success false: {cal.message[:120]}"]
    out += ["outliers"] * bool(cal.outliers) + ["suspects"] * bool(cal.suspects)
    if cal.unidentifiable != clean_unidentifiable:
        out.append("unidentifiable parameters differ")
    return out


def judge_points(folder: Path, arm: ap.Arm, clean: np.ndarray, q_test: np.ndarray,
                 tool_test: np.ndarray | None, sigma: float, must_match: bool,
                 clean_unidentifiable: list[str], seconds: float = 30.0) -> tuple[str, str]:
    """Return (verdict, detail) for a mutated points campaign; verdict "FAIL" on a failure.

    The result is the prediction of new poses (``q_test``), compared with the clean one up to the
    base frame (:func:`aligned_change`) within what the fit's noise explains
    (:func:`points_tolerance`, ``sigma`` the stated point noise).
    """
    notes: list[str] = []
    out, verdict = attempt(lambda: run_points(folder, arm, q_test, tool_test), seconds, notes)
    if verdict:
        return verdict
    cal, points = out
    change = aligned_change(clean, points) if np.all(np.isfinite(points)) else np.inf
    tol = points_tolerance(cal, sigma)
    if change <= tol:
        return "same", ""
    detail = f"new poses moved {change * 1e6:.3g} um (noise explains {tol * 1e6:.3g} um)"
    if must_match:
        return "FAIL", detail + " for a mutation that keeps the meaning"
    if found := flags(cal, clean_unidentifiable) + notes:
        return "flagged", f"{detail}; {', '.join(found)}"
    return "FAIL", detail + ", accepted without a flag"


# ---------------------------------------------------------------- calibration mutations

def _load_json(folder: Path) -> Any:
    return json.loads((folder / "parameters.json").read_text())


def _dump_json(folder: Path, data: Any) -> None:
    (folder / "parameters.json").write_text(json.dumps(data, indent=2))


def _json_slots(data: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path to a value in a JSON document (keys and list indices)."""
    out = [prefix] if prefix else []
    if isinstance(data, dict):
        for k, v in data.items():
            out += _json_slots(v, (*prefix, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            out += _json_slots(v, (*prefix, i))
    return out


def _get(data: Any, path: tuple[Any, ...]) -> Any:
    for k in path:
        data = data[k]
    return data


def _set(data: Any, path: tuple[Any, ...], value: Any) -> None:
    _get(data, path[:-1])[path[-1]] = value


def _slot(data: Any, rng: np.random.Generator) -> tuple[Any, ...]:
    slots = _json_slots(data)
    return slots[int(rng.integers(len(slots)))]


BAD_JSON_VALUES: tuple[Any, ...] = ("abc", "", None, True, [], {}, [1.0], {"a": 1}, float("nan"),
                                    float("inf"), 1e300, -1e300, "0.001", [[[[[[[[[1]]]]]]]]])


def c_wrong_value(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    slot = _slot(data, rng)
    value = BAD_JSON_VALUES[int(rng.integers(len(BAD_JSON_VALUES)))]
    _set(data, slot, value)
    _dump_json(folder, data)
    return f"parameters.json: {'.'.join(map(str, slot))} = {value!r}"


def c_delete_key(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    slot = _slot(data, rng)
    parent = _get(data, slot[:-1])
    del parent[slot[-1]]
    _dump_json(folder, data)
    return f"parameters.json: {'.'.join(map(str, slot))} deleted"


def c_rename_key(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    dict_slots = [s for s in _json_slots(data) if isinstance(_get(data, s[:-1]), dict)]
    slot = dict_slots[int(rng.integers(len(dict_slots)))]
    parent = _get(data, slot[:-1])
    new = [str(slot[-1]).upper(), str(slot[-1]) + "_", "0", "-1", "8", " 1", "1.0", "01"][
        int(rng.integers(8))]
    if new in parent:
        return "parameters.json: nothing renamed"
    parent[new] = parent.pop(slot[-1])
    _dump_json(folder, data)
    return f"parameters.json: key {'.'.join(map(str, slot))} renamed {new!r}"


def c_nest(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    slot = _slot(data, rng)
    depth = int(rng.integers(1, 40))
    value = _get(data, slot)
    for _ in range(depth):
        value = [value] if rng.random() < 0.5 else {"x": value}
    _set(data, slot, value)
    _dump_json(folder, data)
    return f"parameters.json: {'.'.join(map(str, slot))} nested {depth} deep"


def c_truncate(folder: Path, rng: np.random.Generator) -> str:
    name = ["parameters.json", "calibrated.urdf"][int(rng.integers(2))]
    data = (folder / name).read_bytes()
    n = int(rng.integers(len(data)))
    (folder / name).write_bytes(data[:n])
    return f"{name}: truncated to {n} of {len(data)} bytes"


def c_garbage(folder: Path, rng: np.random.Generator) -> str:
    name = ["parameters.json", "calibrated.urdf"][int(rng.integers(2))]
    data = (folder / name).read_bytes()
    n = int(rng.integers(len(data) + 1))
    junk = rng.integers(0, 256, int(rng.integers(1, 32)), dtype=np.uint8).tobytes()
    (folder / name).write_bytes(data[:n] + junk + data[n:])
    return f"{name}: {len(junk)} random bytes at byte {n}"


def c_delete_file(folder: Path, rng: np.random.Generator) -> str:
    name = ["parameters.json", "calibrated.urdf"][int(rng.integers(2))]
    (folder / name).unlink()
    return f"{name}: deleted"


def c_wrong_arm(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    data["arm"] = ["aacmm6", "nothere.urdf", "/dev/zero", "../calibrated.urdf", "", ".",
                   "aacmm7"][int(rng.integers(7))]
    _dump_json(folder, data)
    return f"parameters.json: arm = {data['arm']!r}"


def c_map_length(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    axes = data["encoder_maps"]["axes"]
    n = [0, 1, 71, 73, 144][int(rng.integers(5))]
    axes[str(int(rng.integers(1, 8)))] = [1e-6] * n
    _dump_json(folder, data)
    return f"parameters.json: a map of {n} values"


def c_step(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    step = [0, -5, 7, "5", 1e-9, 360, 720, None][int(rng.integers(8))]
    data["encoder_maps"]["step_deg"] = step
    _dump_json(folder, data)
    return f"parameters.json: step_deg = {step!r}"


def c_units(folder: Path, rng: np.random.Generator) -> str:
    data = _load_json(folder)
    data["units"] = ["mm", "si", 1, None][int(rng.integers(4))]
    _dump_json(folder, data)
    return f"parameters.json: units = {data['units']!r}"


def c_urdf_entity(folder: Path, rng: np.random.Generator) -> str:
    path = folder / "calibrated.urdf"
    text = path.read_text()
    head, _, rest = text.partition("<robot")
    path.write_text(head + '<!DOCTYPE robot [<!ENTITY e "0.1">]>\n<robot' + rest)
    return "calibrated.urdf: an internal entity declared"


def c_urdf_drop_joint(folder: Path, rng: np.random.Generator) -> str:
    path = folder / "calibrated.urdf"
    text = path.read_text()
    starts = [i for i in range(len(text)) if text.startswith("<joint ", i)]
    i = starts[int(rng.integers(len(starts)))]
    j = text.index("</joint>", i) + len("</joint>")
    path.write_text(text[:i] + text[j:])
    return "calibrated.urdf: a joint removed"


C_SAME_NAMES = ("crlf", "bom", "reindent", "key order", "extra key", "report deleted",
                "maps csv deleted")


def c_same(folder: Path, rng: np.random.Generator) -> str:
    """A change that keeps the meaning (line endings, BOM, layout, unknown key, side files)."""
    k = int(rng.integers(len(C_SAME_NAMES)))
    path = folder / "parameters.json"
    data = _load_json(folder)
    if k == 0:
        path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    elif k == 1:
        path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    elif k == 2:
        path.write_text(json.dumps(data, separators=(",", ":")))
    elif k == 3:
        path.write_text(json.dumps(dict(reversed(list(data.items()))), indent=1))
    elif k == 4:
        data["comment"] = {"by": "fuzz", "n": [1, 2]}
        _dump_json(folder, data)
    elif k == 5:
        (folder / "report.json").unlink()
    else:
        (folder / "encoder_maps.csv").unlink()
    return f"calibration: {C_SAME_NAMES[k]}"


def c_value_change(folder: Path, rng: np.random.Generator) -> str:
    """A plausible value changed: another calibration, which the files cannot tell apart."""
    data = _load_json(folder)
    name = list(data["dh"])[int(rng.integers(len(data["dh"])))]
    data["dh"][name] = -data["dh"][name] if rng.random() < 0.5 else data["dh"][name] * 1.5
    _dump_json(folder, data)
    return f"parameters.json: dh.{name} changed (plausible value)"


C_OTHER = (c_wrong_value, c_delete_key, c_rename_key, c_nest, c_truncate, c_garbage,
           c_delete_file, c_wrong_arm, c_map_length, c_step, c_units, c_urdf_entity,
           c_urdf_drop_joint)
"""Calibration mutations that must be refused or give the clean prediction."""

CALIBRATION_TOL = 1e-9
"""Largest change of a predicted point accepted as the clean prediction, m (same numbers)."""


def run_calibration(folder: Path, campaign: ap.Campaign) -> tuple[np.ndarray, dict[Any, float]]:
    """Run the user's path on a calibration folder: read, check, predict and validate."""
    params = ap.read_parameters(folder)
    arm = ap.load_arm(params.arm)
    check_against_arm(params, arm)
    assert campaign.lengthbar is not None
    points = ap.predict(arm, params, campaign.lengthbar.q)
    return points, bar_errors(ap.validate(arm, params, campaign))


def judge_calibration(folder: Path, campaign: ap.Campaign, clean: np.ndarray, kind: str,
                      seconds: float = 30.0) -> tuple[str, str]:
    """Return (verdict, detail) for a mutated calibration; kind "same", "other" or "changed"."""
    try:
        with time_limit(seconds):
            points, _ = run_calibration(folder, campaign)
    except Hang as exc:
        return "FAIL", f"hang: {exc}"
    except Exception as exc:  # noqa: BLE001 - the verdict names every other exception
        if _refused(exc):
            return ("FAIL", f"refused a mutation that keeps the meaning: {exc}") if (
                kind == "same") else ("refused", str(exc).splitlines()[-1][:200])
        return "FAIL", f"{type(exc).__name__}: {exc}"
    diff = float(np.max(np.abs(points - clean))) if points.shape == clean.shape else np.inf
    if diff <= CALIBRATION_TOL:
        return "same", ""
    if kind == "changed":
        return "changed", f"points moved {diff * 1e6:.3g} um"
    return "FAIL", f"predicted points moved {diff * 1e6:.3g} um, accepted without a flag"


Mutation = Callable[[Path, np.random.Generator], str]


def copy_folder(src: Path, dst: Path) -> Path:
    """Copy a folder (replacing ``dst``)."""
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(src, dst)
    return dst
