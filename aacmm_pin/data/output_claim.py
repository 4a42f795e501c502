"""An output claimed at a command's start: :func:`claim_output`, :func:`check_output`.

Every command that writes a folder or a file claims it before any work: an exclusive lock on a
hidden file beside it (``.<name>.lock``; ``flock``, which the kernel releases when the process ends,
even by SIGKILL), then a check of the target: absent, an empty folder, or ``force``; and none of
the command's inputs (the files and folders it reads) is the target or inside it. A second run
into the same output fails at once with one line, instead of replacing the first one's result
unseen. The lock file is removed when the claim ends (a killed run leaves it; the next one takes it
over, saying so, as it removes the temporary files a killed run left: :func:`remove_leftovers`).

Only a lock file made here is ever written: one already at the lock's path is opened read-only,
never through a link, and only when it is a plain file holding a process id; anything else there
(a link to a campaign file, a folder, a hard link) is refused and left as it is. A forked child
(a worker) closes its copies of the lock files, so that it cannot keep an output busy.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import stat
import sys
import threading
import warnings
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from aacmm_pin.errors import AacmmError, StaleOutputWarning
from aacmm_pin.interrupts import interrupts_deferred

if sys.platform != "win32":
    import fcntl

_HELD: dict[tuple[str, int], int] = {}
"""(lock file, thread) -> depth of the claims this process holds (a writer inside a command's claim)."""
_FDS: set[int] = set()
"""Descriptors of the lock files this process holds."""


def _forget_claims() -> None:
    """In a forked child (a worker): close its copies of the lock files, hold no claim.

    A copy open in a child keeps the lock (``flock`` belongs to the open file, which parent and
    child share): a worker that outlived its killed parent would keep the output busy.
    """
    for fd in _FDS:
        try:
            os.close(fd)
        except OSError:
            pass
    _FDS.clear()
    _HELD.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_claims)


class OutputExistsError(AacmmError):
    """The output cannot be written: it holds files (without ``force``), it is an input, or it is busy."""

    def __init__(self, path: Path, reason: str):
        self.path = path
        super().__init__(f"{path}: {reason}")


CAMPAIGN_FILES = ("spat.csv", "locations.csv", "lengthbar.csv", "bar.csv", "points.csv",
                  "campaign.json")
"""The files the campaign reader reads in a campaign folder."""
CALIBRATION_FILES = ("parameters.json", "calibrated.urdf", "calibrated.sizes.json", "report.json",
                     "encoder_maps.csv")
"""The files of a calibration folder (:mod:`aacmm_pin.outputs.calibration_folder`)."""


def input_paths(*paths: str | Path | None, campaigns: Iterable[str | Path | None] = (),
                calibrations: Iterable[str | Path | None] = ()) -> list[Path]:
    """Return what a command reads, to be kept from its outputs (``inputs`` of :func:`check_output`).

    Args:
        paths: files (or folders) read; those that do not exist and None are left out.
        campaigns: campaign folders: each with the files of :data:`CAMPAIGN_FILES` in it.
        calibrations: calibration folders (or parameters files; a ``parameters.json`` stands for
            its folder): each with the files of :data:`CALIBRATION_FILES` in it.
    """
    found = [Path(p) for p in paths if p is not None]
    for names, folders in ((CAMPAIGN_FILES, campaigns), (CALIBRATION_FILES, calibrations)):
        for folder in (Path(f) for f in folders if f is not None):
            if not folder.is_dir() and folder.name == names[0] == CALIBRATION_FILES[0]:
                folder = folder.parent  # a parameters.json: its folder's report, URDF, maps are read
            found += [folder, *(folder / name for name in names)] if folder.is_dir() else [folder]
    return [p for p in found if p.exists()]


def lock_path(target: str | Path) -> Path:
    """Return the lock file of an output: ``.<name>.lock`` beside it."""
    target = Path(target).absolute()
    return target.parent / f".{target.name}.lock"


def _same_or_inside(inner: Path, outer: Path) -> bool:
    """Whether ``inner`` is ``outer`` or lies inside it (links resolved; hard links too)."""
    a, b = inner.resolve(), outer.resolve()
    if a == b or b in a.parents:
        return True
    try:
        return inner.exists() and outer.exists() and os.path.samefile(inner, outer)
    except OSError:
        return False


def check_inputs(target: str | Path, inputs: Iterable[str | Path]) -> None:
    """Refuse an output that is one of the command's inputs, or a folder that holds one.

    Raises:
        OutputExistsError: naming the output and the input (whatever ``force`` says: writing it
            would destroy what the command reads).
    """
    target = Path(target)
    for given in inputs:
        path = Path(given)
        if path.exists() and _same_or_inside(path, target):
            what = "is" if path.resolve() == target.resolve() else "holds"
            raise OutputExistsError(target, f"{what} an input of this command ({path}); "
                                            "choose another output")


def check_output(target: str | Path, force: bool = False, inputs: Iterable[str | Path] = (),
                 folder: bool = True) -> Path:
    """Check that ``target`` can be written; return it.

    Args:
        target: the output folder (``folder``) or file.
        force: replace an existing output (a folder with files, an existing file).
        inputs: the files and folders the command reads: none may be the target or inside it.
        folder: whether the output is a folder (else a file).

    Raises:
        OutputExistsError: if it exists and holds data (and not ``force``), is of the other kind
            (a file for a folder or the reverse), a file stands where one of its parent folders
            should be, or it is (or holds) an input.
    """
    target = Path(target)
    for above in target.absolute().parents:  # a file on the way: say so before any work
        if above.exists():
            if not above.is_dir():
                raise OutputExistsError(above, "is a file, not a folder; choose another output")
            break
    check_inputs(target, inputs)
    if not (target.exists() or target.is_symlink()):
        return target
    if folder:
        if not target.is_dir() or target.is_symlink():
            raise OutputExistsError(target, "exists and is not a folder; choose another output")
        if not force and any(target.iterdir()):
            raise OutputExistsError(target, "exists and is not empty; give --force (force=True) "
                                            "to replace it whole, or choose another output")
    elif target.is_dir():
        raise OutputExistsError(target, "is a folder, not a file; choose another output")
    elif not force:
        raise OutputExistsError(target, "exists; give --force (force=True) to replace it, or "
                                        "choose another output")
    return target


@contextmanager
def claim_output(target: str | Path, force: bool = False, inputs: Iterable[str | Path] = (),
                 folder: bool = True) -> Iterator[Path]:
    """Hold ``target`` for the block: lock it, check it (:func:`check_output`), yield it.

    A writer inside the block (:func:`~aacmm_pin.data.output_folder.output_folder`,
    :func:`~aacmm_pin.data.output_file.output_file`) claims the same target again in the same
    thread: that only checks it. Parent folders are created.

    Raises:
        OutputExistsError: if another process (or thread) holds it, or see :func:`check_output`.
        OSError: if the lock file cannot be created (read-only folder), naming the target.
    """
    target = Path(target)
    inputs = list(inputs)
    lock = lock_path(target)
    key = (str(lock), threading.get_ident())
    if key in _HELD:  # the command's own claim: check again, hold on
        check_output(target, force, inputs, folder)
        _HELD[key] += 1
        try:
            yield target
        finally:
            _HELD[key] -= 1
        return
    check_output(target, force, inputs, folder)  # a file on the way: before creating folders
    created = [p for p in (lock.parent, *lock.parent.parents) if not p.exists()]
    fd = -1
    try:
        with interrupts_deferred():  # a Ctrl-C now arrives inside this try: no lock file left
            with named_os_error(target, lock.parent):  # a read-only folder: named by the output
                lock.parent.mkdir(parents=True, exist_ok=True)
                fd = _lock(lock, target)
                _FDS.add(fd)
            _HELD[key] = 1
        remove_leftovers(target)  # of runs killed while writing it
        check_output(target, force, inputs, folder)  # what the lock's holder may have written
        yield target
    finally:
        if fd >= 0:
            with interrupts_deferred():  # a second Ctrl-C: after the lock file is gone
                _release(lock, fd, key, created, target)


def _release(lock: Path, fd: int, key: tuple[str, int], created: list[Path], target: Path) -> None:
    """Give up a claim: forget it, remove its lock file and the folders made for it if empty."""
    _HELD.pop(key, None)
    _FDS.discard(fd)
    if sys.platform == "win32":  # an open file cannot be removed there
        os.close(fd)
    try:
        lock.unlink()  # while locked (POSIX): a run waiting on it takes a new one
    except OSError:
        pass
    if sys.platform != "win32":
        os.close(fd)
    for made in created if not target.exists() else []:  # nothing written: no empty folders
        try:
            made.rmdir()
        except OSError:
            break


def _busy(target: Path, holder: str) -> OutputExistsError:
    """Return the error of an output another run holds (``holder``: its process id, if read)."""
    return OutputExistsError(target, "another run is writing it"
                             + (f" (process {holder})" if holder.isdigit() else "")
                             + "; wait for it to end or choose another output")


def pid_alive(pid: int) -> bool:
    """Return whether process ``pid`` exists on this host (another user's counts)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:  # e.g. a pid beyond the system's range
        return False
    return True


_CREATE = os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC | getattr(os, "O_NOFOLLOW", 0)
"""A new lock file: created here or not at all (``O_EXCL`` also refuses a link at its path)."""
_INSPECT = os.O_RDONLY | os.O_CLOEXEC | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
"""An existing lock file, opened to read its holder and to test its lock: never written to."""
_NO_FLOCK = (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL)
"""``flock`` errors of a file system that has none (some NFS and FUSE mounts)."""
LOCK_TEXT = re.compile(rb"\d{0,20}\n?")
"""What a lock file of aacmm_pin holds: its holder's process id and a newline (or nothing yet)."""


def _lock(lock: Path, target: Path) -> int:
    """Create ``lock``, take its exclusive lock without waiting, write our pid; return its descriptor.

    Only a file made here (``O_EXCL``) is written to. One already there is opened read-only,
    without following a link, and only when it is a plain file that holds a process id: its
    holder runs (the output is busy), or it is stale (its holder is gone: it is removed and a new
    one made, and :class:`StaleOutputWarning` says so). Without ``flock`` (Windows, or a file
    system that refuses it) the lock is the file's exclusive creation and a stale file is one
    whose process id names no running process.
    """
    if sys.platform == "win32":
        return _lock_by_creation(lock, target)
    for _ in range(100):  # other runs may create and remove it meanwhile
        try:
            fd = os.open(lock, _CREATE, 0o644)
        except FileExistsError:
            _remove_if_stale(lock, target)
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (*_NO_FLOCK, errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                os.close(fd)
                raise
            if exc.errno not in _NO_FLOCK:  # a run that found it empty holds it for a moment
                os.close(fd)
                raise _busy(target, "") from None
        if _same_file(fd, lock):
            try:
                os.ftruncate(fd, 0)  # (made empty here: a no-op that fails like a write)
                os.write(fd, f"{os.getpid()}\n".encode("ascii"))
            except OSError:  # e.g. no space left: the lock file goes (it is ours, locked)
                lock.unlink(missing_ok=True)
                os.close(fd)
                raise
            return fd
        os.close(fd)  # removed as stale by a run that found it empty: make another
    raise OutputExistsError(target, f"its lock file {lock} keeps changing; try again")


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` (not followed) is the file open as ``fd``."""
    try:
        return os.path.samestat(os.fstat(fd), os.lstat(path))
    except FileNotFoundError:
        return False


def _not_a_lock(lock: Path, why: str) -> OutputExistsError:
    """Return the error of a lock path that holds something else (left as it is)."""
    return OutputExistsError(lock, f"{why}, not a lock file of aacmm-pin; it is left as it is: "
                                   "remove it, or choose another output")


def _remove_if_stale(lock: Path, target: Path) -> None:
    """Look at the lock file another run made: raise if it is held or not a lock; else remove it.

    Raises:
        OutputExistsError: the holder runs (naming its pid), or the path is a link, a folder,
            a file with other names (hard links) or other content: refused, left as it is.
    """
    try:
        seen = os.lstat(lock)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(seen.st_mode):
        raise _not_a_lock(lock, f"is a link (to {os.readlink(lock)})")
    if not stat.S_ISREG(seen.st_mode):
        raise _not_a_lock(lock, "is not a plain file")
    try:
        fd = os.open(lock, _INSPECT)
    except FileNotFoundError:
        return
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise _not_a_lock(lock, "is a link") from None
        raise
    try:
        info = os.fstat(fd)
        if not os.path.samestat(info, seen) or not stat.S_ISREG(info.st_mode):
            return  # replaced meanwhile: look again
        if info.st_nlink != 1:
            raise _not_a_lock(lock, f"has {info.st_nlink} names (a hard link)")
        text = os.read(fd, 64)
        if not LOCK_TEXT.fullmatch(text):
            raise _not_a_lock(lock, f"holds other data ({info.st_size} bytes)")
        holder = text.decode("ascii").strip()
        held, alive = _held(fd), bool(holder) and pid_alive(int(holder))
        if held is not False and (alive or not holder):  # (no pid yet: its maker writes it)
            raise _busy(target, holder)
        if _same_file(fd, lock):  # a free lock, or one its dead holder's children kept
            lock.unlink(missing_ok=True)
            if holder:
                why = "not holding it" if alive else "no longer running"
                warnings.warn(StaleOutputWarning(
                    f"took over the stale lock {lock} of process {holder} ({why})"), stacklevel=4)
    finally:
        os.close(fd)


def _held(fd: int) -> bool | None:
    """Whether another process holds the flock of ``fd`` (None: no flock on this file system).

    A free lock is taken (and kept until ``fd`` is closed), so that no other run takes it meanwhile.
    """
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in _NO_FLOCK or exc.errno == errno.EBADF:
            return None
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return True
        raise
    return False


def _lock_by_creation(lock: Path, target: Path) -> int:
    """Create ``lock`` exclusively and write the process id in it; return its descriptor."""
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        raise _busy(target, lock.read_text("ascii", "replace").strip()) from None
    os.write(fd, f"{os.getpid()}\n".encode("ascii"))
    return fd


def temp_prefix(target: Path) -> str:
    """Return the name prefix of a temporary file or folder of ``target``: ``.<name>.<pid>.``.

    The process id tells a later run whose it is: one of a process no longer running is a killed
    run's leftover (:func:`remove_leftovers`).
    """
    return f".{target.name}.{os.getpid()}."


def remove_leftovers(target: Path) -> list[Path]:
    """Remove what killed runs left beside ``target``; return the paths removed.

    Hidden temporary files and folders of ``target`` (``.<name>.<pid>.<8 characters>.tmp``, or
    ``.old``: a folder set aside) whose process is no longer running. Called with the output
    claimed: no live run of this process writes them. Says so in one :class:`StaleOutputWarning`.
    """
    target = Path(target).absolute()
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(\d+)\.[a-z0-9_]{{8}}\.(tmp|old)")
    removed, size = [], 0
    try:
        entries = list(os.scandir(target.parent))
    except OSError:
        return []
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if not match or int(match[1]) == os.getpid() or pid_alive(int(match[1])):
            continue
        try:
            size += _size(Path(entry.path))
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
        except OSError:
            continue
        removed.append(Path(entry.path))
    if removed:
        warnings.warn(StaleOutputWarning(
            f"removed {len(removed)} leftover{'s' if len(removed) > 1 else ''} of killed runs "
            f"beside {target} ({', '.join(p.name for p in removed[:3])}"
            f"{', ...' if len(removed) > 3 else ''}; {size / 1e6:.1f} MB)"), stacklevel=2)
    return removed


def _size(path: Path) -> int:
    """Return the bytes of a file, or of the files in a folder (links not followed)."""
    if not path.is_dir() or path.is_symlink():
        return path.lstat().st_size
    return sum(p.lstat().st_size for p in path.rglob("*") if not p.is_dir() or p.is_symlink())


@contextmanager
def named_os_error(target: Path, hidden: Path | None = None) -> Iterator[None]:
    """Re-raise an OSError of the block that names no file, or a file in ``hidden``, as one naming ``target``.

    "No space left on device" alone names no file; a hidden temporary file means nothing to a user.
    """
    try:
        yield
    except OSError as exc:
        name = exc.filename
        if name is not None and (hidden is None or not _same_or_inside(Path(name), hidden)):
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(target)) from exc


def umask() -> int:
    """Return the process's umask.

    Read from ``/proc/self/status`` where there is one (Linux): setting it to read it, the only
    portable way, changes it for a moment for every thread (acquisition runs threads).
    """
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o077)  # the brief change errs on the private side
    os.umask(mask)
    return mask


def sync_folder(folder: str | Path) -> None:
    """Flush a folder's entries to disk (after a rename in it), where the system allows it.

    Without it a power loss right after ``os.replace`` can lose the rename on some file systems.
    Folders cannot be opened on Windows, and some file systems refuse ``fsync`` on one: skipped.
    """
    if sys.platform == "win32":
        return
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
