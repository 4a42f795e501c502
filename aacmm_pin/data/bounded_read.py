"""Read a file's bytes up to a bound, in chunks: a huge file or ``/dev/zero`` fails fast and cheap."""

from __future__ import annotations

from pathlib import Path

CHUNK = 2**20
"""Bytes read at a time (a single ``read(bound)`` would reserve the whole bound at once)."""


def read_bounded(path: Path, bound: int) -> bytes | None:
    """Return the bytes of a file of at most ``bound`` bytes, or None if it is larger.

    Memory is the file's size (plus one chunk), never the bound: ``f.read(bound + 1)`` reserves
    ``bound`` bytes even for a small file.

    Raises:
        OSError: if the file cannot be read.
    """
    parts: list[bytes] = []
    size = 0
    with path.open("rb") as f:
        while size <= bound and (part := f.read(min(CHUNK, bound + 1 - size))):
            parts.append(part)
            size += len(part)
    return None if size > bound else b"".join(parts)
