"""Output folders written whole or not at all: :func:`output_folder`.

Every command that writes a folder (a calibration, a simulated campaign, a discovery, an
uncertainty study) writes it into a temporary folder beside the target, then puts it in place in
one rename (Linux ``renameat2(RENAME_EXCHANGE)`` swaps it with an existing folder atomically; else
the old folder is renamed aside first). A process killed at any moment leaves the old folder or
the new one, never a mix (at worst a hidden ``.<name>.<pid>.*.tmp`` folder beside it, which the
next run into it removes). An existing, non-empty folder is replaced only when asked (``force``,
the CLI's ``--force``), never when it is or holds one of the command's inputs; the folder is
claimed for as long as the block runs (:func:`~aacmm_pin.data.output_claim.claim_output`: a
second run into it fails at once). An operating-system error while writing (a full disk) names
the folder; the old one stays.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from aacmm_pin.data.output_claim import (
    OutputExistsError,
    check_output,
    claim_output,
    named_os_error,
    sync_folder,
    temp_prefix,
    umask,
)
from aacmm_pin.machine import libc

__all__ = ["OutputExistsError", "check_output", "claim_output", "output_folder"]

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2); return False where unsupported."""
    try:
        renameat2 = libc().renameat2  # type: ignore[union-attr]
    except AttributeError:  # not Linux, or a C library without renameat2
        return False
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: file system or kernel cannot
        return False
    raise OSError(err, os.strerror(err), str(b))


def _fsync_tree(folder: Path) -> None:
    """Flush every file of ``folder`` and the folder itself to disk."""
    for path in [*folder.rglob("*"), folder]:
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextmanager
def output_folder(target: str | Path, force: bool = False, inputs: Iterable[str | Path] = ()
                  ) -> Iterator[Path]:
    """Yield a temporary folder to write into; on success it replaces ``target`` whole.

    Args:
        target: the output folder.
        force: replace an existing, non-empty folder (its files are all removed).
        inputs: files and folders the command reads: none may be the target or inside it.

    Raises:
        OutputExistsError: see :func:`~aacmm_pin.data.output_claim.check_output` (checked
            before anything is written), or another run holds the folder.
        OSError: if the parent folder cannot be written or a write fails (full disk), naming
            ``target``; nothing is left behind and the old folder is intact.
    """
    target = Path(target)
    with claim_output(target, force, inputs, folder=True):
        parent = target.absolute().parent
        with named_os_error(target, parent):
            tmp = Path(tempfile.mkdtemp(prefix=temp_prefix(target), suffix=".tmp", dir=parent))
        try:
            with named_os_error(target, tmp):
                yield tmp
                _fsync_tree(tmp)
                tmp.chmod(0o755 & ~umask())
                _put_in_place(tmp, target)
                sync_folder(parent)  # the rename itself on disk
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def _put_in_place(tmp: Path, target: Path) -> None:
    """Replace ``target`` by ``tmp`` (``tmp`` then holds the old folder, if any, or is gone)."""
    if target.exists() and _exchange(tmp, target):
        return  # tmp now holds the old folder
    if target.exists():  # two renames: a kill between them leaves the old one aside
        old = target.absolute().parent / f"{tmp.name[:-4]}.old"
        os.replace(target, old)
        os.replace(tmp, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, target)
