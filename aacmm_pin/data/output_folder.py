"""Output folders written whole or not at all: :func:`output_folder`.

Every command that writes a folder (a calibration, a simulated campaign, a discovery, an
uncertainty study) writes it into a temporary folder beside the target, then puts it in place in
one rename (Linux ``renameat2(RENAME_EXCHANGE)`` swaps it with an existing folder atomically; else
the old folder is renamed aside first). A process killed at any moment leaves the old folder or
the new one, never a mix (at worst a hidden ``.<name>.*.tmp`` folder beside it). An existing,
non-empty folder is replaced only when asked (``force``, the CLI's ``--force``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from aacmm_pin.errors import AacmmError

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


class OutputExistsError(AacmmError):
    """The output folder exists and holds files; it is replaced only with ``force``."""

    def __init__(self, path: Path, reason: str):
        self.path = path
        super().__init__(f"{path}: {reason}")


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2); return False where unsupported."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError, TypeError):
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


def check_output(target: str | Path, force: bool = False) -> Path:
    """Check that ``target`` can be written: absent, an empty folder, or ``force``; return it.

    Raises:
        OutputExistsError: if it is a non-empty folder (and not ``force``), not a folder, or a
            file stands where one of its parent folders should be.
    """
    target = Path(target)
    for above in target.absolute().parents:  # a file on the way: say so before any work
        if above.exists():
            if not above.is_dir():
                raise OutputExistsError(above, "is a file, not a folder; choose another output")
            break
    if target.exists() or target.is_symlink():
        if not target.is_dir() or target.is_symlink():
            raise OutputExistsError(target, "exists and is not a folder; choose another output")
        if not force and any(target.iterdir()):
            raise OutputExistsError(target, "exists and is not empty; give --force (force=True) "
                                            "to replace it whole, or choose another output")
    return target


@contextmanager
def output_folder(target: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder to write into; on success it replaces ``target`` whole.

    Args:
        target: the output folder.
        force: replace an existing, non-empty folder (its files are all removed).

    Raises:
        OutputExistsError: see :func:`check_output` (checked before anything is written).
        OSError: if the parent folder cannot be written (nothing is left behind).
    """
    target = check_output(target, force)
    parent = target.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=parent))
    try:
        yield tmp
        _fsync_tree(tmp)
        tmp.chmod(0o755 & ~_umask())
        if target.exists() and _exchange(tmp, target):
            pass  # tmp now holds the old folder
        elif target.exists():  # two renames: a kill between them leaves the old one aside
            old = parent / f"{tmp.name[:-4]}.old"
            os.replace(target, old)
            os.replace(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _umask() -> int:
    """Return the process's umask."""
    mask = os.umask(0)
    os.umask(mask)
    return mask
