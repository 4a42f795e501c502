"""Output files written whole or not at all: :func:`output_file`, :func:`write_text_file`.

The file's text goes to a temporary file beside it (``.<name>.<pid>.*.tmp``), flushed to disk, then
replaces it in one rename: a process killed at any moment, or a disk that fills up, leaves the
old file or the new one, never a fragment (a killed run's temporary file is removed by the next
run into the file). An existing file is replaced only when asked (``force``,
the CLI's ``--force``), never when it is one of the command's inputs; the file is claimed
(:func:`~aacmm_pin.data.output_claim.claim_output`) for as long as the block runs, so a command
that claims it at its start holds it from before its work to the rename.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from aacmm_pin.data.output_claim import (
    claim_output,
    named_os_error,
    sync_folder,
    temp_prefix,
    umask,
)


@contextmanager
def output_file(target: str | Path, force: bool = False, inputs: Iterable[str | Path] = ()
                ) -> Iterator[Path]:
    """Yield a temporary path to write the file to; on success it replaces ``target``.

    Args:
        target: the output file.
        force: replace an existing file.
        inputs: files and folders the command reads: the target may be none of them.

    Raises:
        OutputExistsError: see :func:`~aacmm_pin.data.output_claim.check_output`.
        OSError: a write that failed (full disk, ...), naming ``target``; the old file is intact
            and no temporary file is left.
    """
    target = Path(target)
    with claim_output(target, force, inputs, folder=False):
        with named_os_error(target, target.absolute().parent):
            fd, name = tempfile.mkstemp(prefix=temp_prefix(target), suffix=".tmp",
                                        dir=target.absolute().parent)
        os.close(fd)
        tmp = Path(name)
        try:
            with named_os_error(target, tmp):
                yield tmp
                fd = os.open(tmp, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
                os.chmod(tmp, 0o666 & ~umask())
                os.replace(tmp, target)
                sync_folder(target.absolute().parent)  # the rename itself on disk
        finally:
            tmp.unlink(missing_ok=True)


def write_text_file(target: str | Path, text: str, force: bool = False,
                    inputs: Iterable[str | Path] = ()) -> Path:
    """Write ``text`` (UTF-8) to ``target`` through :func:`output_file`; return the path."""
    with output_file(target, force, inputs) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(target)
