"""The lock of a results folder: one batch writes to a folder at a time.

Two batches writing into one folder used to merge into the same temporary name and delete
each other's parts while reading them (a raw FileNotFoundError in most trials, finished
rows lost in some).  A batch now holds ``DIR/.lock`` from before it reads the folder until
after it has merged the parts:

* the lock is an advisory ``flock`` on that file (POSIX): the kernel releases it when its
  process dies, however it dies (SIGKILL included), so a dead batch never blocks the next;
  the file itself stays (deleting a lock file races with a process about to lock it);
* the file says who holds it (pid, host, start time, as JSON), for the message of a batch
  that finds the folder locked -- which waits up to ``timeout`` seconds, then raises
  :class:`~compass_sparse.exceptions.FolderLockedError` naming the owner;
* a lock file whose pid is not running is not in the way: the lock is free and is taken
  over (logged);
* processes forked while the lock is held (a local process pool's workers) close their
  copy of the descriptor at once, so that a worker outliving its batch does not keep the
  lock;
* where ``fcntl`` is missing (Windows), the file is created exclusively instead and a file
  left by a pid that is not running on this host is taken over.
"""
from __future__ import annotations

import json
import logging
import os
import socket
import threading
import time
from datetime import datetime, timezone

from ..exceptions import FolderLockedError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

logger = logging.getLogger("compass_sparse")

__all__ = ["LOCK_FILE", "FolderLock"]

LOCK_FILE = ".lock"
POLL = 0.2
"""Seconds between two tries of a locked folder."""

_HELD: set = set()  # descriptors of the locks this process holds (closed in forked children)
_HELD_GUARD = threading.Lock()


def _close_in_child():
    for fd in list(_HELD):
        try:
            os.close(fd)
        except OSError:
            pass
    _HELD.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_in_child)


def _pid_running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # someone else's process, or unknown: assume running
    return True


def read_owner(path) -> dict:
    """The owner written in a lock file ({} when unreadable)."""
    try:
        with open(path, encoding="utf-8") as fh:
            owner = json.loads(fh.read() or "{}")
        return owner if isinstance(owner, dict) else {}
    except (OSError, ValueError):
        return {}


def _describe(owner: dict) -> str:
    if not owner:
        return "another batch"
    return (f"another batch (pid {owner.get('pid', '?')} on {owner.get('host', '?')}, "
            f"since {owner.get('started', '?')})")


class FolderLock:
    """``with FolderLock(folder, timeout):`` holds the folder's lock (see the module)."""

    def __init__(self, folder, timeout: float = 0.0):
        self.folder = os.fspath(folder)
        self.path = os.path.join(self.folder, LOCK_FILE)
        self.timeout = float(timeout)
        self.fd = None
        self.me = {"pid": os.getpid(), "host": socket.gethostname(),
                   "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}

    def __enter__(self):
        self.acquire()
        return self

    def __exit__(self, *exc):
        self.release()

    def acquire(self):
        deadline = time.monotonic() + self.timeout
        while True:
            owner = self._try()
            if owner is None:
                return
            if time.monotonic() >= deadline:
                raise FolderLockedError(
                    f"the results folder {self.folder} is in use by {_describe(owner)}: "
                    "wait for it to finish (or give lock_timeout), or write to another "
                    "folder", owner)
            time.sleep(min(POLL, max(0.0, deadline - time.monotonic())))

    def _try(self):
        """None when the lock is now ours, else the owner's record."""
        if fcntl is None:  # pragma: no cover - Windows
            return self._try_exclusive()
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except (BlockingIOError, PermissionError):
            os.close(fd)
            return read_owner(self.path)
        except OSError:
            os.close(fd)
            raise
        old = read_owner(self.path)
        if old:  # its owner did not release it: it died (the kernel freed the lock)
            logger.info("batch: took over the lock of %s, which is not running",
                        _describe(old))
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps(self.me).encode())
        os.fsync(fd)
        self.fd = fd
        with _HELD_GUARD:
            _HELD.add(fd)
        return None

    def _try_exclusive(self):  # pragma: no cover - Windows
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            old = read_owner(self.path)
            here = old.get("host") == self.me["host"]
            if here and isinstance(old.get("pid"), int) and not _pid_running(old["pid"]):
                logger.info("batch: took over the lock of %s, which is not running",
                            _describe(old))
                os.replace(self.path, self.path + f".stale-{os.getpid()}")
                return self._try_exclusive()
            return old
        os.write(fd, json.dumps(self.me).encode())
        os.fsync(fd)
        self.fd = fd
        return None

    def release(self):
        fd, self.fd = self.fd, None
        if fd is None:
            return
        with _HELD_GUARD:
            _HELD.discard(fd)
        if fcntl is None:  # pragma: no cover - Windows
            os.close(fd)
            os.remove(self.path)
            return
        try:
            os.ftruncate(fd, 0)  # released: a lock file that still names a pid was not
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
