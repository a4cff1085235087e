"""One call run in a forked child process while this one goes on, when that is safe and useful.

``identify`` uses it to fit transfer functions while the state-space stages run, and to read a
case's second log while it reads the first. Results are the same as running the call in place.
"""

from __future__ import annotations

__all__ = ["Background"]


class Background:
    """``fn(*args)`` in a forked child process when ``fork`` and the machine allow, else right here.

    It forks only on Linux (macOS system libraries are not fork-safe), with a second core, from a
    single-threaded process (a child forked while other threads hold locks, as in a notebook
    kernel or beside a Zenoh session, can deadlock); otherwise the call runs here. :meth:`result`
    returns the value or raises the exception; a child that dies without an answer (killed, out of
    memory) is not waited on forever: the call then runs here instead.
    """

    def __init__(self, fn, *args, fork: bool = True):
        import multiprocessing
        import os
        import sys
        import threading

        self._call, self._pool, self._future = (fn, args), None, None
        if (fork and sys.platform.startswith("linux") and (os.cpu_count() or 1) >= 2
                and threading.active_count() == 1):
            from concurrent.futures import ProcessPoolExecutor

            try:
                self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"))
                self._future = self._pool.submit(fn, *args)
            except (OSError, RuntimeError):        # no processes left, or not allowed here
                self._close()

    def result(self):
        from concurrent.futures.process import BrokenProcessPool

        if self._future is not None:
            try:
                return self._future.result()
            except BrokenProcessPool:
                pass
            finally:
                self._close()
        fn, args = self._call
        return fn(*args)

    def _close(self) -> None:
        if self._pool is not None:      # the answer is in: the child exits at once (and the next may fork)
            self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool, self._future = None, None
