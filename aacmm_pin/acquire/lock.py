"""One writer per campaign folder: ``acquire`` holds ``<campaign>/.acquire.lock`` while it records.

The lock is an advisory ``flock`` on the lock file, which holds the pid of its holder. The kernel
drops the lock when its holder ends, however it ends (SIGKILL included): a lock file left by a dead
process is stale and taken over, and the takeover is reported. A second ``acquire`` into a folder
whose lock is held refuses before it opens a port or writes anything.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from aacmm_pin.acquire.faults import AcquisitionError
from aacmm_pin.data.output_claim import pid_alive

LOCK_NAME = ".acquire.lock"
"""Name of the lock file inside the campaign folder."""


class CampaignLock:
    """The exclusive right to append to one campaign folder.

    The lock file is removed on release; a run killed before that leaves it, with its pid, and the
    next run takes it over.

    Args:
        folder: campaign folder (created if needed).

    Raises:
        AcquisitionError: if another process holds the lock (its pid is named), or the lock file
            cannot be created.
    """

    def __init__(self, folder: str | Path):
        self.path = Path(folder) / LOCK_NAME
        self.message = ""
        """What happened to an earlier lock file (a stale one taken over), or ''."""
        self._fd: int | None = None
        for _ in range(100):  # another run may remove the file between our open and our lock
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.read(fd, 64).decode("ascii", "replace").strip() or "unknown"
                os.close(fd)
                raise AcquisitionError(
                    f"{self.path.parent} is being recorded by another acquire (pid {holder}, lock "
                    f"file {self.path}): wait for it to end, stop it, or record into another "
                    f"campaign folder") from None
            try:
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)  # we locked a file its holder removed on release: try the new one
        else:
            raise AcquisitionError(f"{self.path}: cannot take the lock (it keeps changing)")
        previous = os.read(fd, 64).decode("ascii", "replace").strip()
        if previous:
            alive = previous.isdigit() and pid_alive(int(previous))
            self.message = (f"took over the stale lock {self.path} of pid {previous} "
                            f"({'not holding it' if alive else 'no longer running'})")
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd

    def _open(self) -> int:
        """Open (create) the lock file; return its descriptor."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            return os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise AcquisitionError(f"{self.path}: cannot create the lock file: "
                                   f"{exc.strerror or exc}") from None

    def release(self) -> None:
        """Remove the lock file and release the lock (idempotent)."""
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self._fd)  # closing drops the flock
            self._fd = None

    def __enter__(self) -> CampaignLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
