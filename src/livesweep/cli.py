"""The ``livesweep`` command.

Verbs: ``sim`` (simulate a test point to MCAP and/or live MAVLink), ``monitor`` (live sweep
monitor), ``replay`` (the monitor over a recording), ``identify`` (frequency responses from a case
file) and ``demo`` (the one command a newcomer runs first). Bad input prints one line ``livesweep: error: ...`` and exits 2.

This module parses (:mod:`livesweep.cli_parser`) and dispatches to the verb's command
(:mod:`livesweep.commands`), which calls the library and prints; it also turns errors and signals
into exit statuses.
"""

from __future__ import annotations

import os
import sys

from livesweep.cli_parser import EXAMPLES, build_parser
from livesweep.commands.campaign import cmd_campaign
from livesweep.commands.common import counts_text as _counts_text
from livesweep.commands.demo import cmd_demo
from livesweep.commands.identify import cmd_identify
from livesweep.commands.logs import EXIT_DATA_LOST, cmd_convert, cmd_inspect, cmd_maps, cmd_new_case, cmd_recover
from livesweep.commands.monitor import _recorded_settings, cmd_monitor, cmd_replay
from livesweep.commands.monitor import monitor_settings as _monitor_settings
from livesweep.commands.monitor_summary import ALIGNER_WORDS as _ALIGNER_WORDS
from livesweep.commands.sim import cmd_sim, cmd_stream, default_axis
from livesweep.errors import LivesweepError

# livesweep.cli also offers the commands and the helpers scripts and tests use, from livesweep.commands
__all__ = ["main", "build_parser", "EXAMPLES", "EXIT_USAGE", "EXIT_DATA_LOST", "cmd_sim", "cmd_stream", "cmd_monitor",
           "cmd_replay", "cmd_identify", "cmd_demo", "cmd_convert", "cmd_inspect", "cmd_new_case", "cmd_recover",
           "cmd_maps", "cmd_campaign", "_counts_text", "_ALIGNER_WORDS", "_monitor_settings", "_recorded_settings"]

EXIT_USAGE = 2


#: Commands whose linear algebra is many small problems (fits, SVDs of a few hundred points):
#: a BLAS thread pool costs more than it gains there, so they run single-threaded unless the user
#: set the variables (measured: the residual stage 60 % and a whole identify about 30 % faster).
_SMALL_BLAS_VERBS = ("identify", "batch", "demo")
_BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


class _Signalled(SystemExit):
    """Raised in the main thread by SIGTERM or SIGHUP (:func:`_unwind_on_signals`); exit status
    ``128 + signal number``, as the signal itself would have given."""

    def __init__(self, signum: int):
        import signal

        super().__init__(128 + signum)
        self.name = signal.Signals(signum).name


def _unwind_on_signals() -> dict:
    """Make SIGTERM (``kill``, ``timeout``, systemd, ``docker stop``) and SIGHUP (a closed terminal)
    raise :class:`_Signalled` instead of ending the process where it stands, so ``with`` blocks and
    ``finally`` clauses run: an atomic writer deletes its ``.partial`` file, locks are released.

    A signal ignored when the process started (``nohup``) stays ignored. A second signal ends the
    process at once (the default action), should the unwinding itself hang. Commands that finish
    their work on a signal (``monitor``) install their own handlers, which replace these. Nothing
    is installed outside the main thread (Python runs signal handlers only there).

    Returns
    -------
    dict
        Signal -> the handler replaced, for :func:`main` to put back when the command returns.
    """
    import signal
    import threading

    def handler(signum, frame):
        signal.signal(signum, signal.SIG_DFL)
        raise _Signalled(signum)

    replaced = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(sig) == signal.SIG_DFL:
                replaced[sig] = signal.signal(sig, handler)
    return replaced


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    verb = next((a for a in argv if not a.startswith("-")), None)
    if verb in _SMALL_BLAS_VERBS and "numpy" not in sys.modules:   # before anything loads numpy (the parser does)
        for var in _BLAS_THREAD_VARS:
            os.environ.setdefault(var, "1")
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "axis", None) is None and args.verb == "sim":
        args.axis = [default_axis(args.model)]
    replaced = _unwind_on_signals()
    try:
        return args.func(args)
    except LivesweepError as exc:
        print(f"livesweep: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("livesweep: interrupted", file=sys.stderr)
        return 130
    except _Signalled as exc:
        print(f"livesweep: {exc.name}: stopped", file=sys.stderr)
        return exc.code
    finally:
        import signal

        for sig, previous in replaced.items():
            signal.signal(sig, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
