"""One writer per output: an exclusive, non-blocking lock held while a command writes a folder.

``livesweep identify --out DIR`` and ``livesweep batch --out DIR`` each hold ``DIR/.livesweep.lock``
(``flock``) while they write, so a second process aiming at the same folder fails at once with a
clear error instead of mixing its files with the first one's. The owner deletes the lock file when
it is done (while still holding the lock), so a finished run leaves no litter; the lock itself goes
with the process, so the file a killed run leaves behind blocks nothing. Because the file can be
deleted under a process that has just opened it, an acquirer checks after locking that the file it
locked is still the one under that name (device and inode) and starts again if not: whoever holds
the lock on the file at ``DIR/.livesweep.lock`` owns the folder, and only the owner removes it.

A file has one owner too. A writer that writes a file in place (a live recording) holds an ``flock``
on the file itself while it writes (:class:`livesweep.telemetry.mcap_log.McapLogWriter`). A writer
that writes ``<file>.partial`` and renames it (``sim``, ``convert``, ``recover``) asks
:func:`check_file_free` before it starts and installs its result with :func:`install_file`, which
never renames over a file another process holds, ``--force`` or not: a recording in progress cannot
be replaced behind its writer's back.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

from livesweep.errors import ConfigError

__all__ = ["LOCK_NAME", "check_file_free", "folder_lock", "install_file"]

#: The lock file a writing command keeps in its output folder while it writes (deleted when it is done).
LOCK_NAME = ".livesweep.lock"


@contextmanager
def folder_lock(folder, what: str = "--out"):
    """Hold the exclusive lock of ``folder`` (which must exist) for the ``with`` block; the lock
    file is deleted when the block ends (a killed process leaves it, harmless: the lock went with it).

    Raises
    ------
    ConfigError
        Naming ``what`` and the folder, when another process holds the lock or the lock file
        cannot be made.
    """
    path = Path(folder) / LOCK_NAME
    fd = _lock_current_file(path, folder, what)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        try:                        # delete it while still holding it, and only if it is still ours
            if _same_inode(fd, path):
                os.unlink(path)
        except OSError:             # gone already, or a read-only folder: the lock still goes with the fd
            pass
        os.close(fd)


def _same_inode(fd: int, path: Path) -> bool:
    """True when ``path`` names the file open as ``fd`` (same device and inode)."""
    try:
        st, now = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (st.st_dev, st.st_ino) == (now.st_dev, now.st_ino)


def _lock_current_file(path: Path, folder, what: str) -> int:
    """Open (or make) the lock file ``path`` and lock it, non-blocking; returns the fd.

    An owner deletes the file on release, so the file opened here may have been unlinked (and
    perhaps replaced by another acquirer's) before the lock was taken: after locking, the locked
    file must still be the one at ``path``, else it is closed and the whole is tried again.
    """
    import fcntl

    for _ in range(100):                # each turn ends in the lock, a refusal, or a file that changed under us
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
        except OSError as e:
            raise ConfigError(f"{what} {str(folder)!r}: cannot make its lock file ({e.strerror or e})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise ConfigError(f"{what} {str(folder)!r}: another livesweep process is writing into it") from None
        if _same_inode(fd, path):
            return fd
        os.close(fd)                    # its owner released and deleted it meanwhile: take the file there now
    raise ConfigError(f"{what} {str(folder)!r}: its lock file {LOCK_NAME} keeps changing under this process; "
                      "another livesweep process is using the folder")


def _held_elsewhere(fd: int) -> bool:
    """True when another open file (another process, or another writer here) holds ``fd``'s file
    locked; the lock taken to find out is kept (the caller closes ``fd`` to release it)."""
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    return False


def check_file_free(path, *, overwrite: bool, what: str = "--out", error=ConfigError) -> None:
    """Fail before any work when ``path`` may not be written.

    Parameters
    ----------
    path : str or Path
        The file a command is about to write (through ``<path>.partial`` and a rename).
    overwrite : bool
        An existing file may be replaced (``--force``); never one another process is writing.
    what : str
        How the user named it (an option), for the message.
    error : type
        The :class:`~livesweep.errors.LivesweepError` subclass raised.

    Raises
    ------
    error
        One line naming the file: it is being written by another process, or it exists and
        ``overwrite`` is False.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return
    except OSError:                 # cannot be opened to look (a directory, no permission): the writer says why
        return
    try:
        if _held_elsewhere(fd):
            raise error(f"{what} {path}: another process is writing it (a file being recorded is never replaced, "
                        "--force or not)")
    finally:
        os.close(fd)
    if not overwrite:
        raise error(f"{what} {path} exists; it is not overwritten unless asked (--force)")


def install_file(tmp, path, *, overwrite: bool, what: str = "--out", error=ConfigError) -> None:
    """Move the finished file ``tmp`` onto ``path``, never over a file another process is writing.

    A new name is made with ``link`` (which never replaces anything), so a recording that started
    under that name meanwhile is kept. An existing file is replaced (``rename``) only when
    ``overwrite`` is True and only while this process holds its lock, after checking that the
    locked file is still the one under that name.

    Parameters
    ----------
    tmp : str or Path
        The finished file, in the same folder as ``path``; gone after a successful call.
    path : str or Path
        The destination.
    overwrite : bool
        Replace an existing ``path`` (``--force``).
    what, error
        As :func:`check_file_free`.

    Raises
    ------
    error
        As :func:`check_file_free`; ``tmp`` is left in place for the caller to delete.
    """
    tmp, path = Path(tmp), Path(path)
    for _ in range(100):                       # each turn ends in success, a refusal, or a file that changed under us
        try:
            os.link(tmp, path)
        except FileExistsError:
            pass
        except OSError:                        # no hard links on this file system: replace a name found free
            if not os.path.lexists(path):
                os.replace(tmp, path)
                return
        else:
            os.unlink(tmp)
            return
        if not overwrite:
            raise error(f"{what} {path} exists; it is not overwritten unless asked (--force)")
        try:
            fd = os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            continue
        try:
            if _held_elsewhere(fd):
                raise error(f"{what} {path}: another process is writing it (a file being recorded is never "
                            "replaced, --force or not)")
            try:
                st, now = os.fstat(fd), os.stat(path)
            except FileNotFoundError:
                continue
            if (st.st_dev, st.st_ino) == (now.st_dev, now.st_ino):
                os.replace(tmp, path)
                return
        finally:
            os.close(fd)
    raise error(f"{what} {path}: the file keeps changing under this process; nothing was written")
