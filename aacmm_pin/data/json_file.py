"""Every JSON file the package reads, read one way: bounded, strict about keys, errors with the file.

:func:`read_json` reads at most a stated number of bytes (a huge file or ``/dev/zero`` fails
fast), refuses an object that names a key twice (``json`` would keep the last one silently), an
object with more keys than any file of the package needs, and nesting deeper than the caller
allows; every refusal is one :class:`~aacmm_pin.errors.FileFormatError` line naming the file.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from aacmm_pin.data.bounded_read import read_bounded
from aacmm_pin.errors import FileFormatError, Problem

MAX_OBJECT_KEYS = 4096
"""Most keys of one JSON object read. The largest object a file of the package holds is
``parameters.json``'s ``dh``: at most 6 error frames per axis, and an arm has at most 256 axes
(:data:`aacmm_pin.data.csv_table.MAX_COLUMNS`), 1,536 keys; 4096 leaves room for the tools and
for a plugin's extensions, and refuses a million keys in milliseconds instead of minutes."""


MAX_FILE_KEYS = 4 * MAX_OBJECT_KEYS
"""Most keys of a whole JSON file read: four objects of the largest size. Counted on the text
before parsing (a colon outside strings is a key's), so that a million keys are refused without
building them."""
_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')


class JsonKeyError(FileFormatError):
    """A well-formed JSON file that names a key twice in one object, or has too many keys."""


class _Refused(ValueError):
    """A JSON object the reader refuses (a repeated key, too many keys); its message says why."""

    def __init__(self, key: str | None, reason: str):
        super().__init__(reason)
        self.key = key
        self.reason = reason


def _strict_object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """Return a JSON object's pairs as a dict; raise :class:`_Refused` on a repeated key."""
    if len(pairs) > MAX_OBJECT_KEYS:
        raise _Refused(None, f"an object with {len(pairs):,} keys; the package's files need at "
                             f"most {MAX_OBJECT_KEYS:,}")
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Refused(key, "key given twice in one object (JSON would keep the last one "
                                "silently): keep one")
        out[key] = value
    return out


def loads(text: str, path: Path | str, max_file_keys: int | None = MAX_FILE_KEYS) -> Any:
    """Return the content of JSON text, refusing repeated and too many keys.

    ``max_file_keys``: most keys in the whole text (None: bounded by its size only, for a file the
    package writes with one small object per sample, such as ``report.json``'s outliers).

    Raises:
        FileFormatError: one problem naming ``path`` (and the key, or the line and column of a
            syntax error); a :class:`JsonKeyError` for a repeated key or too many keys.
    """
    if (max_file_keys is not None and len(text) > max_file_keys
            and (keys := _STRING.sub("", text).count(":")) > max_file_keys):
        raise JsonKeyError([Problem(path, None, None, f"{keys:,} keys; the package's files need "
                                                      f"at most {max_file_keys:,}")])
    try:
        return json.loads(text, object_pairs_hook=_strict_object)
    except _Refused as exc:
        raise JsonKeyError([Problem(path, None, exc.key, exc.reason)]) from None
    except json.JSONDecodeError as exc:
        raise FileFormatError([Problem(path, exc.lineno, f"char {exc.colno}", exc.msg)]) from None
    except RecursionError:
        raise FileFormatError([Problem(path, None, None, "JSON nested too deeply")]) from None


def read_json(path: str | Path, max_bytes: int, what: str,
              max_file_keys: int | None = MAX_FILE_KEYS) -> Any:
    """Read a JSON file of at most ``max_bytes`` bytes (UTF-8, a BOM allowed).

    Args:
        path: the file.
        max_bytes: largest size read, bytes.
        what: what the file is, for the message on a too large file ("a parameters file").
        max_file_keys: most keys in the file (see :func:`loads`).

    Raises:
        FileFormatError: one problem naming the file: missing, unreadable, too large, not UTF-8,
            not JSON (line and column), a key twice in one object, too many keys.
    """
    path = Path(path)
    try:
        raw = read_bounded(path, max_bytes)  # a huge file or /dev/zero fails fast
    except FileNotFoundError:
        raise FileFormatError([Problem(path, None, None, "no such file")]) from None
    except OSError as exc:
        raise FileFormatError([Problem(path, None, None, exc.strerror or str(exc))]) from None
    if raw is None:
        raise FileFormatError([Problem(path, None, None, f"larger than {max_bytes // 2**20} MiB: "
                                                         f"not {what}")])
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError([Problem(path, None, None, f"not UTF-8 text: {exc}")]) from None
    return loads(text, path, max_file_keys)
