"""The monitor as library calls: :func:`replay` over a recording (what ``livesweep replay``
runs) and :func:`monitor` on live links (what ``livesweep monitor`` runs).

:func:`replay` runs an MCAP log through the live monitor's pipeline
(:class:`~livesweep.monitor.pipeline.MonitorPipeline`: aligner, sliding-window estimator, test
points, verdicts, alerts) and returns a frozen :class:`ReplayResult` with what the live run
would have recorded on its ``/livesweep/test_point``, ``/livesweep/verdict`` and
``/livesweep/alert`` channels, as those channels carry it (the same JSON: non-finite numbers as
``"NaN"``, tuples as lists), and the counters the command prints. Headless by default: no Rerun,
no terminal output (the map's warnings go to :mod:`logging`, ``livesweep.monitor.pipeline``).

    >>> import livesweep
    >>> r = livesweep.replay("flight.mcap")                        # doctest: +SKIP
    >>> [(tp["swept_input"], tp["verdict"]) for tp in r.test_points]  # doctest: +SKIP
    [('da', 'GO')]

The settings are the ones the recording carries (the monitor attaches them as
``livesweep_settings.json``; the demo's ``live.mcap`` has them), else the channel map or case
given, else the packaged XV-15 map: as ``livesweep replay`` chooses them.

:func:`monitor` runs the same pipeline on live links (MAVLink, Zenoh) in a background thread and
returns a running :class:`Monitor`: its test points, verdicts and alerts grow as the recording's
channels get them; :meth:`Monitor.stop` finishes the recording and returns the summary.

    >>> with livesweep.monitor("udpin:0.0.0.0:14550", map="ardupilot-copter-quad-x",
    ...                        record="flight.mcap") as live:                # doctest: +SKIP
    ...     time.sleep(600)
    ...     print(live.verdict, [tp["label"] for tp in live.test_points])
"""

from __future__ import annotations

import atexit
import json
import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path

from livesweep.errors import ConfigError
from livesweep.monitor.settings_choice import (DEFAULT_MAP, map_settings, recorded_settings, replay_settings,
                                               with_options)

__all__ = ["ReplayResult", "replay", "replay_settings", "recorded_settings", "map_settings", "with_options",
           "Monitor", "monitor", "DEFAULT_MAP"]

#: The live results kept in order (:attr:`Monitor.events`), by their ``/livesweep/<name>`` channel.
EVENTS = ("test_point", "verdict", "alert", "model")
#: What a recording made by :func:`monitor` says made it, unless ``metadata`` says otherwise.
DEFAULT_METADATA = {"test_point": {"source": "livesweep.monitor()"}}


@dataclass(frozen=True)
class ReplayResult:
    """What a replay of one log gave.

    Attributes
    ----------
    path : Path
        The log replayed.
    settings : MonitorSettings
        The settings it ran with.
    settings_source : str
        Where they came from: ``"recording"`` (the log's ``livesweep_settings.json``), ``"case"``,
        ``"map"``, ``"default"`` (the packaged XV-15 map) or ``"settings"`` (given).
    test_points : tuple of dict
        Every closed test point, in order, as ``/livesweep/test_point`` carries it (``source``,
        ``swept_input``, ``start_s``, ``end_s``, ``verdict``, ``label``, ``pairs``, ``reasons``, ...).
    verdicts : tuple of dict
        Every change of the operator's verdict, as ``/livesweep/verdict`` carries it (``t_s``,
        ``verdict``, ``previous``, ``reasons``, ``test_point``).
    alerts : tuple of dict
        Every alert raised, as ``/livesweep/alert`` carries it (``t_s``, ``kind``, ``message``,
        ``value``).
    models : tuple of dict
        The model of each closed test point that had a band to fit, as ``/livesweep/model``
        carries it (``test_point``, ``pairs``, ``breaches``, ``trend``, ...).
    counters : dict
        The final counters the command's summary prints: ``sources`` (per source), ``aligner``
        (repairs and gaps) and ``pipeline``.
    link : dict or None
        The last ``/livesweep/link`` record (the counters as recorded at the end).
    summary : dict
        Everything :meth:`MonitorPipeline.run` returned (frames, estimates, ``data_s``,
        ``wall_s``, ``verdict``, ``reasons``, ``map_problems``, ...): what ``livesweep replay`` prints.
    recording : Path or None
        The MCAP the replay recorded (``record=``), else None.
    """

    path: Path
    settings: object
    settings_source: str
    test_points: tuple
    verdicts: tuple
    alerts: tuple
    counters: dict
    link: dict | None
    summary: dict
    recording: Path | None = None
    models: tuple = ()

    @property
    def verdict(self) -> str | None:
        """The operator's verdict at the end (``"GO"``, ``"NO-GO"``, ``"WAIT"``), None before any."""
        return self.summary.get("verdict")


def _as_recorded(payload: dict) -> dict:
    """``payload`` as the recording's JSON channel carries it (what a reader decodes)."""
    try:
        text = json.dumps(payload, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError):
        from livesweep.numeric import json_safe

        text = json.dumps(json_safe(payload)[0], separators=(",", ":"), allow_nan=False)
    return json.loads(text)


class _Results:
    """The live results as the recording's channels carry them, kept as the pipeline hands them
    over (its ``results`` callback, in its own thread); read from any thread."""

    def __init__(self):
        self._lock = threading.Lock()
        self._events: list[tuple[str, dict]] = []
        self._last: dict[str, dict] = {}
        self._counters: dict | None = None
        #: The pipeline's :meth:`~MonitorPipeline.counters`, snapshotted with each link record.
        self.counters_of = None

    def __call__(self, name: str, payload: dict) -> None:
        if name not in EVENTS and name != "link":
            return                                   # estimates: many, and not kept
        rec = _as_recorded(payload)
        counters = self._snapshot() if name == "link" else None
        with self._lock:
            self._last[name] = rec
            if name != "link":
                self._events.append((name, rec))
            if counters is not None:
                self._counters = counters

    def _snapshot(self) -> dict | None:
        if self.counters_of is None:
            return None
        import copy

        try:                                        # a source's reader thread may be adding a key
            return copy.deepcopy(self.counters_of())
        except RuntimeError:
            return None

    def events(self) -> tuple:
        with self._lock:
            return tuple(self._events)

    def of(self, name: str) -> tuple:
        with self._lock:
            return tuple(p for n, p in self._events if n == name)

    def last(self, name: str) -> dict | None:
        with self._lock:
            return self._last.get(name)

    def counters(self) -> dict | None:
        with self._lock:
            return self._counters


def _view(rerun, settings, name: str = "replay"):
    """The Rerun view ``rerun`` asks for: None/False none, True the desktop viewer, a path an .rrd
    file, a dict :class:`~livesweep.monitor.rerun_view.RerunView`'s keywords (``save_path``,
    ``spawn``, ``serve``, ``bind_host``, ``recording_id``), anything else a view object as it is."""
    if rerun is None or rerun is False:
        return None
    if rerun is True or isinstance(rerun, (str, os.PathLike, dict)):
        from livesweep.monitor.rerun_view import RerunView

        options = dict(rerun) if isinstance(rerun, dict) else {"save_path": None if rerun is True else rerun,
                                                               "spawn": rerun is True}
        return RerunView(list(settings.inputs), list(settings.outputs),
                         **{"recording_id": name, "min_coherence": settings.criteria.min_coherence, **options})
    return rerun


def _given_view(rerun):
    """The view object ``rerun`` is, when it is one (the call that gets it closes it)."""
    return None if rerun is None or isinstance(rerun, (bool, str, os.PathLike, dict)) else rerun


def _close(parts) -> None:
    """Close each part once, the first error aside (the caller's own error is the one to see)."""
    seen = set()
    for part in parts:
        if part is None or id(part) in seen:
            continue
        seen.add(id(part))
        try:
            part.close()
        except Exception:  # noqa: BLE001 - closing after a failure must not hide it
            pass


def replay(path, case=None, map=None, *, settings=None, record=None, rerun=None, speed: float = 0.0,
           overwrite: bool = False) -> ReplayResult:
    """Run the monitor over the MCAP log ``path``, as ``livesweep replay`` does.

    Parameters
    ----------
    path : str or os.PathLike
        An MCAP log: a monitor's recording, the demo's ``live.mcap``, a converted log
        (``livesweep.convert.convert``).
    case, map : str or os.PathLike, optional
        A case or map file, or a map preset's name (``livesweep maps``), in place of the settings
        the recording carries (one of the two). Default: the recording's, else the packaged
        XV-15 map.
    settings : MonitorSettings, optional
        Exactly these settings (not with ``case`` or ``map``); checked against the monitor's limits.
    record : str or os.PathLike, optional
        Also write an MCAP recording of the replay: every frame replayed and the live results,
        with the settings attached (so it replays again). An existing file is refused unless
        ``overwrite``; never the log itself.
    rerun : bool, str, os.PathLike, dict or view, optional
        None (default): headless. A path: the Rerun recording to that ``.rrd`` file. True: the
        Rerun desktop viewer. A dict: :class:`~livesweep.monitor.rerun_view.RerunView`'s keywords
        (``serve=True`` for the web viewer). A view object is used as it is; it is closed when
        the replay ends.
    speed : float
        0 (default): as fast as possible; N: N x the log's own pace.
    overwrite : bool
        Replace an existing ``record`` file.

    Returns
    -------
    ReplayResult

    Raises
    ------
    ConfigError
        A missing log, both a case and a map, settings beyond the monitor's limits, a bad speed.
    LogFormatError
        A log that is not MCAP; a ``record`` file that exists.
    """
    from livesweep.monitor.pipeline import MonitorPipeline
    from livesweep.telemetry.replay import McapReplaySource

    view = _given_view(rerun)
    frames = recorder = None
    kept = _Results()
    try:                     # a view handed in is the replay's to close, also when it cannot start
        log = Path(path)
        if not log.is_file():
            raise ConfigError(f"log {str(path)!r} does not exist")
        chosen, source = replay_settings(path, case, map, settings=settings)
        frames = McapReplaySource(path, speed=speed or 0.0)      # named as given (the counters say it)
        view = _view(rerun, chosen)
        if record is not None:              # the recording last: nothing after it can fail but the pipeline
            if Path(record).resolve() == log.resolve():
                raise ConfigError(f"record {str(record)!r} is the log being replayed; give another file")
            from livesweep.telemetry.recorder import McapRecorder

            recorder = McapRecorder(record, settings=chosen.to_dict(), overwrite=overwrite,
                                    metadata={"test_point": {"source": "livesweep replay", "log": str(path)}})
        pipe = MonitorPipeline(chosen, [frames], recorder=recorder, view=view, keep_estimates=False, results=kept)
    except BaseException:
        _close((frames, recorder, view))
        raise
    summary = pipe.run()
    return ReplayResult(path=log, settings=chosen, settings_source=source, test_points=kept.of("test_point"),
                        verdicts=kept.of("verdict"), alerts=kept.of("alert"), counters=summary["counters"],
                        link=kept.last("link"), summary=summary,
                        recording=None if recorder is None else Path(recorder.path), models=kept.of("model"))


# -- live --------------------------------------------------------------------------------------------

class Monitor:
    """A live monitor running in a background thread: what :func:`monitor` returns.

    Its results grow while it runs, as the recording's channels get them; each read is a
    snapshot taken under a lock (the dicts are the monitor's own: copy one before changing it).
    :meth:`stop` (or leaving a ``with`` block) finishes the recording and returns the summary.

    Attributes
    ----------
    settings : MonitorSettings
        What it estimates, and how.
    sources : list
        The sources the pipeline reads (the recorder process's UDP links first).
    urls : tuple of str
        Every MAVLink link as bound: ``udpin:127.0.0.1:0`` becomes the port the kernel picked.
    recording : Path or None
        The MCAP file it records (``record=``).
    layout : Path or None
        The Foxglove layout written next to the recording.
    """

    def __init__(self, pipeline, results: _Results, *, settings, sources, duration_s=None, capture=None,
                 status_line=None, recording=None, layout=None):
        self._pipe, self._results = pipeline, results
        self._duration_s = duration_s
        self._capture, self._status_line = capture, status_line
        self.settings = settings
        self.sources = list(sources)
        bound = list(capture.urls) if capture is not None and capture.source in self.sources else []
        self.urls = tuple(bound + [s.description for s in self.sources
                                   if hasattr(s, "url") and (capture is None or s is not capture.source)])
        self.recording = None if recording is None else Path(recording)
        self.layout = layout
        self._summary: dict | None = None
        self._error: BaseException | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="livesweep-monitor", daemon=True)
        atexit.register(self._finish_at_exit)      # a monitor left running still finishes its recording
        self._thread.start()

    def _run(self) -> None:
        try:
            self._summary = self._pipe.run(duration_s=self._duration_s)
        except BaseException as e:  # noqa: BLE001 - handed to the thread that stops or waits
            self._error = e
        finally:
            for part in (self._capture, self._status_line):
                if part is None:
                    continue
                try:
                    part.close()
                except BaseException as e:  # noqa: BLE001
                    self._error = self._error or e
            self._done.set()

    def _finish_at_exit(self) -> None:
        if not self._done.is_set():
            self._pipe.request_stop()
            self._done.wait()

    # -- running and stopping ----------------------------------------------------------------
    @property
    def running(self) -> bool:
        """True until the run has ended (stopped, ``duration_s`` over, every source finished, failed)."""
        return not self._done.is_set()

    @property
    def stop_requested(self) -> bool:
        """True once :meth:`request_stop` or :meth:`stop` was called."""
        return self._pipe.stop_requested

    def request_stop(self) -> None:
        """Ask the run to end and return at once (safe in a signal handler); :meth:`wait` for it."""
        self._pipe.request_stop()

    def wait(self, timeout: float | None = None) -> dict | None:
        """Wait for the run to end; its summary (as :meth:`stop`), or None when ``timeout`` [s]
        passed first. Signal handlers of the main thread run while it waits.

        Raises
        ------
        LivesweepError
            Whatever ended the run (a recorder process that died, a link that failed).
        """
        import time

        if threading.current_thread() is self._thread:
            raise RuntimeError("the monitor cannot wait for itself: call request_stop() in its own thread")
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._done.wait(0.1 if deadline is None else max(0.0, min(0.1, deadline - time.monotonic()))):
            if deadline is not None and time.monotonic() >= deadline:
                return None
        atexit.unregister(self._finish_at_exit)
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._summary

    def stop(self) -> dict:
        """Stop: the links drained, the recording finished (summary and index written), sources,
        view and publisher closed. Idempotent: later calls return the same summary.

        Returns
        -------
        dict
            The summary ``livesweep monitor`` prints: ``frames``, ``estimates``, ``data_s`` [s of
            data], ``wall_s`` [s], ``verdict``, ``reasons``, ``test_points``, ``counters``,
            ``aligner``, ``recorded`` (messages per channel), ``map_problems``, ...

        Raises
        ------
        LivesweepError
            Whatever ended the run, on every call.
        """
        self._pipe.request_stop()
        return self.wait()

    def __enter__(self) -> "Monitor":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.stop()
            return
        try:                                        # the block's own error is the one to see
            self.stop()
        except Exception:  # noqa: BLE001
            pass

    # -- results -------------------------------------------------------------------------------
    @property
    def summary(self) -> dict | None:
        """The run's summary once it has ended (:meth:`stop`), else None."""
        return self._summary if self._done.is_set() else None

    @property
    def events(self) -> tuple:
        """Every test point, verdict change, alert and model so far, in order, as ``(channel, dict)``
        with ``channel`` one of ``"test_point"``, ``"verdict"``, ``"alert"``, ``"model"``."""
        return self._results.events()

    @property
    def models(self) -> tuple:
        """The model of each closed test point so far, as ``/livesweep/model`` carries it."""
        return self._results.of("model")

    @property
    def test_points(self) -> tuple:
        """Every closed test point so far, as ``/livesweep/test_point`` carries it (``source``,
        ``swept_input``, ``start_s`` and ``end_s`` [s of data], ``verdict``, ``label``, ``pairs``,
        ``reasons``, ...)."""
        return self._results.of("test_point")

    @property
    def verdicts(self) -> tuple:
        """Every change of the operator's verdict so far, as ``/livesweep/verdict`` carries it
        (``t_s`` [s of data], ``verdict``, ``previous``, ``reasons``, ``test_point``)."""
        return self._results.of("verdict")

    @property
    def alerts(self) -> tuple:
        """Every alert so far, as ``/livesweep/alert`` carries it (``t_s`` [s of data], ``kind``,
        ``message``, ``value``)."""
        return self._results.of("alert")

    @property
    def link(self) -> dict | None:
        """The newest ``/livesweep/link`` record (recorded about once a second), or None."""
        return self._results.last("link")

    @property
    def counters(self) -> dict:
        """The counters: ``sources`` (per source: received, rejected, lost), ``aligner`` (repairs
        and gaps) and ``pipeline``; while running as of the newest link record (at most about
        1 s old), after the stop the final ones."""
        if self.summary is not None:
            return self._summary["counters"]
        return self._results.counters() or {}

    @property
    def verdict(self) -> str | None:
        """The operator's verdict now (``"GO"``, ``"NO-GO"``, ``"WAIT"``), None before any."""
        if self.summary is not None:
            return self._summary["verdict"]
        last = self._results.last("verdict")
        return None if last is None else last["verdict"]

    def __repr__(self) -> str:
        state = "running" if self.running else "stopped"
        return (f"Monitor({state}, {', '.join(self.urls) or len(self.sources)}, "
                f"{len(self.test_points)} test points, verdict {self.verdict})")


def _settings_for(settings, case, map):
    """``settings`` as given (checked), else the map's (:func:`map_settings`)."""
    if settings is not None:
        if case or map:
            raise ConfigError("give settings, or a case or map, not both")
        return settings.check_limits("settings")
    return map_settings(case, map)


def monitor(sources, settings=None, *, case=None, map=None, record=None, overwrite: bool = False, rerun=None,
            signing_key: bytes | None = None, zenoh_config=None, zenoh_listen: int | None = None,
            publish: bool = False, duration_s: float | None = None, status=None, markers=False,
            metadata: dict | None = None, layout: bool = True) -> Monitor:
    """Start the live monitor on ``sources`` in a background thread, as ``livesweep monitor`` does.

    Parameters
    ----------
    sources : str, source object, or list of them
        MAVLink input urls (``"udpin:0.0.0.0:14550"``, ``"udp:127.0.0.1:14550"``,
        ``"tcp:127.0.0.1:5760"``, ``"/dev/ttyUSB0,57600"``; port 0 picks a free port,
        :attr:`Monitor.urls` says which), ``"zenoh:KEYEXPR"`` (JSON samples on a Zenoh key
        expression), or source objects (``livesweep.telemetry.frames.Source``); see
        :mod:`livesweep.monitor.sources`. UDP links are read by a recorder process of their own.
    settings : MonitorSettings, optional
        Exactly these settings (not with ``case`` or ``map``).
    case, map : str or os.PathLike, optional
        A case or map file, or a map preset's name (``livesweep maps``); default: the packaged
        XV-15 map (:func:`map_settings`; :func:`with_options` changes its window, pairs, ...).
    record : str or os.PathLike, optional
        The MCAP file to record: every message as received and the live results, with the
        settings attached (so it replays). An existing file is refused unless ``overwrite``.
    overwrite : bool
        Replace an existing ``record`` file.
    rerun : bool, str, os.PathLike, dict or view, optional
        As :func:`replay`'s: None headless, a path an ``.rrd`` file, True the desktop viewer, a
        dict the view's keywords (``{"serve": True}``: the web viewer), a view object as it is.
    signing_key : bytes, optional
        32-byte MAVLink 2 signing key: unsigned and forged frames are refused and counted.
    zenoh_config : str, os.PathLike or zenoh.Config, optional
        A Zenoh JSON5 config file (routers, TLS) or configuration, for Zenoh sources and ``publish``.
    zenoh_listen : int, optional
        A Zenoh source listens on ``tcp/127.0.0.1:<port>`` (one Zenoh source).
    publish : bool
        Also publish the live results on Zenoh under ``livesweep/...``.
    duration_s : float, optional
        End the run after this much wall time [s]; default: run until :meth:`Monitor.stop`.
    status : text stream, optional
        A one-line status (frames/s, losses, test point, verdict, sweep) once a second, e.g.
        ``sys.stderr``.
    markers : bool or text stream
        Read test-point markers (``s roll``, ``e``) typed in a text stream: True ``sys.stdin``.
    metadata : dict, optional
        The recording's metadata (default: ``{"test_point": {"source": "livesweep.monitor()"}}``).
    layout : bool
        Write a Foxglove layout next to the recording (``flight.foxglove.json``).

    Returns
    -------
    Monitor
        Running; its links are bound and listening when it is returned.

    Raises
    ------
    ConfigError
        One line naming what cannot be used: a source spec, both a case and a map, settings
        beyond the monitor's limits, a bad ``duration_s`` or ``signing_key``.
    LivesweepError, LogFormatError
        A link that cannot be opened or bound; a ``record`` file that exists.

    Notes
    -----
    Source objects and a view object handed in are the monitor's to close: at the stop, and at
    once when the monitor cannot start.
    """
    from livesweep.monitor.sources import open_publisher, open_source, parse_source_spec, zenoh_settings

    if isinstance(sources, (str, os.PathLike)) or hasattr(sources, "poll"):
        sources = [sources]
    specs = list(sources)
    given = [s for s in specs if not isinstance(s, (str, os.PathLike))] + [_given_view(rerun)]
    opened, publisher, view, capture, status_line = [], None, None, None, None
    try:                     # everything that can fail first: the recording (which overwrite truncates) last
        if not specs:
            raise ConfigError("give at least one source: a MAVLink url (udpin:127.0.0.1:14550) or zenoh:KEYEXPR")
        parsed = [parse_source_spec(s) for s in specs]
        chosen = _settings_for(settings, case, map)
        if duration_s is not None and not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s)
                                           and duration_s > 0):
            raise ConfigError(f"duration_s must be > 0 seconds, got {duration_s!r}")
        if signing_key is not None and not (isinstance(signing_key, bytes) and len(signing_key) == 32):
            raise ConfigError("signing_key must be the 32 bytes of a MAVLink 2 signing key")
        zenoh = [p for p in parsed if p.kind == "zenoh"]
        if zenoh_listen is not None and len(zenoh) > 1:
            raise ConfigError(f"zenoh_listen serves one Zenoh source, not {len(zenoh)}; give zenoh_config for several")
        cfg = zenoh_settings(zenoh_config) if zenoh or publish else None
        for p in parsed:
            if p.kind != "udpin":
                opened.append(open_source(p, signing_key=signing_key, zenoh_config=cfg, zenoh_listen=zenoh_listen))
        if publish:
            publisher = open_publisher(cfg, zenoh_listen)
        view = _view(rerun, chosen, "live")
        udp = [p.value for p in parsed if p.kind == "udpin"]
        if udp or record is not None:
            # the UDP links and the recording in a process of their own: a busy analysis cannot starve them
            from livesweep.telemetry.capture import LiveCapture

            capture = LiveCapture(udp, record_path=record, overwrite=overwrite, settings=chosen.to_dict(),
                                  metadata=DEFAULT_METADATA if metadata is None else metadata, signing_key=signing_key)
            if udp:
                opened.insert(0, capture.source)
        written = None
        if record is not None and layout:
            from livesweep.monitor.foxglove import write_layout

            written = write_layout(record, chosen.signals, chosen.inputs, chosen.outputs)
        if markers:
            from livesweep.monitor.markers import MarkerSource

            opened.append(MarkerSource(None if markers is True else markers))
        if status is not None and status is not False:
            from livesweep.monitor.status_line import StatusLine

            status_line = StatusLine(None if status is True else status)
        from livesweep.monitor.pipeline import MonitorPipeline

        results = _Results()
        pipe = MonitorPipeline(chosen, opened, recorder=None if capture is None or record is None else capture.recorder,
                               view=view, publisher=publisher, keep_estimates=False, status_line=status_line,
                               results=results)
        results.counters_of = pipe.counters
        return Monitor(pipe, results, settings=chosen, sources=opened, duration_s=duration_s, capture=capture,
                       status_line=status_line, recording=record, layout=written)
    except BaseException:
        _close((*opened, *given, publisher, view, capture, status_line))
        raise
