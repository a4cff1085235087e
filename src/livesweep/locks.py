"""One writer per output: an exclusive, non-blocking lock held while a command writes a folder.

``livesweep identify --out DIR`` and ``livesweep batch --out DIR`` each hold ``DIR/.livesweep.lock``
(``flock``) while they write, so a second process aiming at the same folder fails at once with a
clear error instead of mixing its files with the first one's. The lock goes with the process: a
killed run leaves nothing that blocks the next one. (MCAP files have their own lock on the file
itself: :class:`livesweep.telemetry.mcap_log.McapLogWriter`.)
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["LOCK_NAME", "folder_lock"]

#: The lock file a writing command keeps in its output folder.
LOCK_NAME = ".livesweep.lock"


@contextmanager
def folder_lock(folder, what: str = "--out"):
    """Hold the exclusive lock of ``folder`` (which must exist) for the ``with`` block.

    Raises
    ------
    ConfigError
        Naming ``what`` and the folder, when another process holds the lock or the lock file
        cannot be made.
    """
    import fcntl

    path = Path(folder) / LOCK_NAME
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
    except OSError as e:
        raise ConfigError(f"{what} {str(folder)!r}: cannot make its lock file ({e.strerror or e})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise ConfigError(f"{what} {str(folder)!r}: another livesweep process is writing into it") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        os.close(fd)
