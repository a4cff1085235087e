"""The live Rerun view of the sweep monitor.

What the engineer sees, and how each item is represented (entity paths: :mod:`.blueprint`):

* **Time series** of inputs and outputs: ``rr.Scalars`` per signal, sent in blocks with
  ``send_columns`` on the ``flight_time`` timeline (a duration; ``round(t_s * 1e9)`` ns; a
  timestamp when the data's clock is seconds since the UNIX epoch, as a receive-time map's is,
  so the time axis reads as the UTC clock rather than 20 000 days). The legend names carry the
  units (``"da [deg]"``).
* **Frequency plots** per pair, all three against ``log10 omega`` with ticks at the 1-2-5 values
  labelled in rad/s: coherence gamma^2 (line and points, 0..1, the threshold 0.6 as an orange
  line), |H| [dB] and phase [deg]. Rerun has no log axis, so each is a ``rr.LineStrips2D`` whose
  points are ``(log10 omega, value)`` in a Spatial2DView with fixed visual bounds; a
  ``rr.Transform3D`` on the entity maps the plotted range onto the view's box (y up) and is
  logged again, at the estimate's time, whenever that range changes; the grid and its labels
  are a child entity, so they get the same transform.
  *Masking*: where gamma^2 < 0.6 the curves are drawn **grey and thin** on all three plots (and
  the coherence points grey); a masked magnitude or phase point outside the plotted range is
  not drawn. The plotted range follows the coherent points (:func:`.freq_plot.value_extent`:
  it grows at once and shrinks when it is more than 1.6 times what the data need).
  *Phase*: unwrapped along frequency and moved by whole turns so its value at the lowest
  coherent frequency lies in (-180, 180] deg.
  The coherence entity also carries ``Coherence:values`` (the exact gamma^2, float64) and
  ``Coherence:kind`` (``"ordinary"`` or ``"partial"``, also written above the plot's axis).
* **Coherence waterfall** per pair: ``rr.Tensor`` of shape (estimates, frequency bins) holding
  gamma^2 in **percent as uint8** (value range 0..100), the last ``waterfall_rows`` estimates with
  the newest in the last row, shown in a TensorView with the viridis colormap. The bins are the
  estimator's log-spaced grid, so its x axis is logarithmic too.
* **Status**: a markdown ``rr.TextDocument`` (verdict, which coherence was judged, the sweep
  frequency and time still needed per input, the reasons, and the adequacy table with
  percentages from :func:`livesweep.monitor.text.percent`), ``status/adequacy_fraction`` (one
  series per pair), ``status/sweep_frequency/<input>`` [rad/s] and ``status/time_remaining/<input>``
  [s] (NaN while unknown).
* **Test points**: a markdown ``rr.TextDocument`` with the open test point and the closed ones.
* **Alerts**: ``rr.TextLog`` at level WARN, text ``"[kind] message"``.

Costs: ``rr.log`` with archetype objects costs ~0.3-1.4 ms per spectral entity (the Python-side
conversion), i.e. >100 ms per update for 48 pairs. The hot path therefore builds the Arrow
arrays itself (``_tensor_array``, ``_strips_array``) and logs them as described component
batches; grids and transforms are logged only when they change.

Viewer modes: ``save_path`` (an ``.rrd`` file with the blueprint), ``spawn`` (the desktop viewer;
blocks ~11 s and fails without a display), ``serve`` (the bundled ``rerun`` CLI as a child process
serving the web viewer and a gRPC proxy bound to ``bind_host`` only; the Python serve functions
bind 0.0.0.0). Sinks combine: saving and serving at once is fine.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import logging
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import weakref
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.encodings.tensor_data_ext import DTYPE_MAP

from livesweep.monitor.blueprint import (
    ADEQUACY_PATH, ALERTS_PATH, BAND_EDGE_PATHS, FOCUS_PATH, FRACTION_PATH, TEST_POINTS_PATH, TIMELINE, check_names,
    default_blueprint, pair_label, pair_path, plot_box, plot_margins, sweep_frequency_path, telemetry_path,
    time_remaining_path, waterfall_path,
)
from livesweep.monitor.freq_plot import (
    MAG_STEPS_DB, PHASE_STEPS_DEG, frequency_extent, log_ticks, masked_runs, reference_phase, tick_label,
    value_extent,
)
from livesweep.monitor.text import EPOCH_MIN_S, adequacy_markdown, coherence_kind_text, markdown_test_points
from livesweep.spectral.adequacy import MIN_COHERENCE

__all__ = ["RerunView", "find_rerun_cli", "series_label", "adequacy_markdown", "serve_banner"]

log = logging.getLogger(__name__)

_MAG_COLOR = (66, 146, 230)
_PHASE_COLOR = (236, 88, 80)
_COH_COLOR = (60, 190, 90)
_MASKED_COLOR = (125, 125, 125, 200)
_THRESHOLD_COLOR = (255, 165, 0)
_GRID_COLOR = (150, 150, 150, 120)
_BAND_EDGE_COLOR = (90, 90, 90)        # the judged band's edges on the sweep-frequency plot: seen at a glance
_GRID_MINOR_COLOR = (150, 150, 150, 45)
_TITLE_COLOR = (40, 40, 40)
#: Line radii [ui points; Rerun encodes ui points as negative radii] of coherent and masked stretches.
_CURVE_RADIUS = -1.5
_MASKED_RADIUS = -0.6


# --------------------------------------------------------------------------------------------
# Arrow fast path (the archetype constructors convert tensors in Python at ~0.5 ms each)
# --------------------------------------------------------------------------------------------

class _Arrow:
    """A ComponentBatchLike around a ready pyarrow array."""

    __slots__ = ("_a",)

    def __init__(self, a: pa.Array) -> None:
        self._a = a

    def as_arrow_array(self) -> pa.Array:
        return self._a


def _descriptors(archetype) -> dict:
    return {b.component_descriptor().component: b.component_descriptor()
            for b in archetype.as_component_batches()}


_TENSOR_T = rr.components.TensorDataBatch._ARROW_DATATYPE
_TENSOR_FIELDS = list(_TENSOR_T)
_SHAPE_T = _TENSOR_T.field("shape").type
_NAMES_T = _TENSOR_T.field("names").type
_BUFFER_T = _TENSOR_T.field("buffer").type
_BUFFER_NULLS = [pa.nulls(0, type=f.type) for f in _BUFFER_T]
_BUFFER_IDX = {dt: [f.name for f in _BUFFER_T].index(name) for dt, name in DTYPE_MAP.items()}
_TYPE_ID_BUF = {i: pa.py_buffer(np.array([i], np.int8)) for i in _BUFFER_IDX.values()}
_OFFSET0_BUF = pa.py_buffer(np.array([0], np.int32))
_STRIP_T = rr.components.LineStrip2DBatch._ARROW_DATATYPE
_POINT_T = rr.components.Position2DBatch._ARROW_DATATYPE


@functools.lru_cache(maxsize=64)
def _shape_array(shape: tuple) -> pa.Array:
    return pa.array([list(shape)], type=_SHAPE_T)


@functools.lru_cache(maxsize=64)
def _names_array(names: tuple | None) -> pa.Array:
    return pa.array([None if names is None else list(names)], type=_NAMES_T)


@functools.lru_cache(maxsize=64)
def _offsets(n: int) -> pa.Array:
    return pa.array([0, n], pa.int32())


def _tensor_array(values: np.ndarray, dim_names: tuple | None = None) -> pa.Array:
    """One TensorData, identical to ``TensorDataBatch(values).as_arrow_array()`` (a test checks).

    ``values`` must not be mutated afterwards (pyarrow wraps the numpy buffer without copying).
    """
    v = np.ascontiguousarray(values)
    idx = _BUFFER_IDX[v.dtype.type]
    inner = pa.ListArray.from_arrays(_offsets(v.size), pa.array(v.ravel()), type=_BUFFER_T[idx].type)
    children = list(_BUFFER_NULLS)
    children[idx] = inner
    buffer = pa.Array.from_buffers(type=_BUFFER_T, length=1, buffers=[None, _TYPE_ID_BUF[idx], _OFFSET0_BUF],
                                   children=children)
    return pa.StructArray.from_arrays([_shape_array(v.shape), _names_array(dim_names), buffer],
                                      fields=_TENSOR_FIELDS)


def _strips_array(strips: list[np.ndarray]) -> pa.Array:
    """LineStrip2D batch from float32 (n_i, 2) arrays."""
    flat = np.concatenate(strips).astype(np.float32, copy=False).ravel() if strips else np.zeros(0, np.float32)
    points = pa.FixedSizeListArray.from_arrays(pa.array(flat), type=_STRIP_T.value_type)
    offsets = np.zeros(len(strips) + 1, np.int32)
    offsets[1:] = np.cumsum([len(s) for s in strips])
    return pa.ListArray.from_arrays(pa.array(offsets), points, type=_STRIP_T)


def _ns(t_s) -> np.ndarray:
    """Seconds -> int64 nanoseconds, rounded (Rerun truncates float arrays; we round everywhere)."""
    return np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)


# --------------------------------------------------------------------------------------------
# The bundled rerun CLI as a web-viewer server bound to one address
# --------------------------------------------------------------------------------------------

def find_rerun_cli() -> list[str]:
    """The command that runs the ``rerun`` CLI binary shipped with rerun-sdk.

    Order: ``$RERUN_CLI_PATH``; the binary inside the ``rerun_cli`` package (preferred: the
    ``bin/rerun`` script is a Python wrapper around it); ``rerun`` next to ``sys.executable``;
    ``rerun`` on PATH. Raises FileNotFoundError naming the places searched.
    """
    tried = []
    env = os.environ.get("RERUN_CLI_PATH")
    if env:
        tried.append(env)
        if os.path.isfile(env) and os.access(env, os.X_OK):
            return [env]
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        cand = Path(spec.origin).parent / ("rerun.exe" if sys.platform.startswith("win") else "rerun")
        tried.append(str(cand))
        if cand.is_file() and os.access(cand, os.X_OK):
            return [str(cand)]
    cand = Path(sys.executable).parent / "rerun"
    tried.append(str(cand))
    if cand.is_file() and os.access(cand, os.X_OK):
        return [str(cand)]
    found = shutil.which("rerun")
    if found:
        return [found]
    tried.append("rerun on PATH")
    raise FileNotFoundError("cannot find the rerun CLI binary; looked at: " + ", ".join(tried))


def _url_host(host: str) -> str:
    if host in ("", "0.0.0.0"):
        return "127.0.0.1"
    if host == "::":
        return "[::1]"
    return f"[{host}]" if ":" in host else host


def _bound_scope(host: str) -> str:
    """``"loopback"`` when ``host`` (an address or a name) binds this machine's loopback only,
    ``"all"`` for the unspecified address (every interface), else ``"network"`` (a name that does not
    resolve counts as reachable: the warning errs on the safe side)."""
    import ipaddress

    name = host.strip("[]")
    if name in ("", "0.0.0.0", "::"):
        return "all"
    try:
        addrs = {ipaddress.ip_address(name)}
    except ValueError:
        try:
            addrs = {ipaddress.ip_address(a[4][0].split("%")[0])
                     for a in socket.getaddrinfo(name, None, proto=socket.IPPROTO_TCP)}
        except (OSError, ValueError):
            return "network"
    if any(a.is_unspecified for a in addrs):
        return "all"
    return "loopback" if addrs and all(a.is_loopback for a in addrs) else "network"


def serve_banner(bind_host: str, web_port: int, grpc_port: int, web_url: str) -> str:
    """The line printed when the web viewer is served: the URL to open, the address its two ports
    are actually bound to and, when that is not a loopback address, a warning in the same line
    (the viewer and its gRPC proxy have no authentication).

    Parameters
    ----------
    bind_host : str
        The address given to ``rerun --bind`` (``--rerun-bind``).
    web_port, grpc_port : int
        The web viewer's and the gRPC proxy's TCP ports.
    web_url : str
        The address to open in a browser on this machine.
    """
    shown = bind_host if bind_host else "0.0.0.0"
    shown = f"[{shown}]" if ":" in shown and not shown.startswith("[") else shown
    bound = f"bound to {shown} ports {int(web_port)} (web) and {int(grpc_port)} (gRPC)"
    scope = _bound_scope(bind_host)
    if scope == "loopback":
        return f"livesweep: Rerun web viewer at {web_url} ({bound}: this machine only)"
    where = "every interface" if scope == "all" else "not a loopback address"
    return (f"livesweep: Rerun web viewer at {web_url} ({bound}: WARNING: {where}, anyone who can reach this "
            "machine on those ports sees the live data, without authentication)")


def _port_open(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host.strip("[]"), port), timeout=0.2):
            return True
    except OSError:
        return False


def _prctl_pdeathsig():
    """A preexec function that makes the child get SIGTERM when this process dies (Linux only)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    sig = int(signal.SIGTERM)

    def _preexec() -> None:  # runs in the forked child: no allocation-heavy work here
        prctl(1, sig)  # PR_SET_PDEATHSIG

    return _preexec


def _stop_process(proc: subprocess.Popen, timeout_s: float = 5.0) -> None:
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)  # its own session: also reaches a wrapper's child
    except (ProcessLookupError, PermissionError, AttributeError):
        proc.terminate()
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError, AttributeError):
            proc.kill()
        proc.wait(timeout=timeout_s)


class _WebViewerServer:
    """``rerun --serve-web --bind HOST --port GRPC --web-viewer-port WEB`` as a child process."""

    def __init__(self, bind_host: str, grpc_port: int, web_port: int, *, start_timeout_s: float = 30.0) -> None:
        self.bind_host, self.grpc_port, self.web_port = bind_host, int(grpc_port), int(web_port)
        self.cmd = [*find_rerun_cli(), "--serve-web", "--bind", bind_host, "--port", str(self.grpc_port),
                    "--web-viewer-port", str(self.web_port)]
        self._log = tempfile.TemporaryFile(mode="w+b")
        self.proc = subprocess.Popen(self.cmd, stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True, preexec_fn=_prctl_pdeathsig())
        self._finalizer = weakref.finalize(self, _stop_process, self.proc)
        h = _url_host(bind_host)
        self.grpc_url = f"rerun+http://{h}:{self.grpc_port}/proxy"
        self.web_url = f"http://{h}:{self.web_port}/?url={urllib.parse.quote(self.grpc_url, safe='')}"
        try:
            self._wait_ready(h, start_timeout_s)
        except BaseException:
            self.stop()
            raise

    def log_text(self) -> str:
        self._log.flush()
        self._log.seek(0)
        return self._log.read().decode("utf-8", "replace")

    def _wait_ready(self, host: str, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            rc = self.proc.poll()
            if rc is not None:
                raise RuntimeError(f"rerun web viewer ({' '.join(self.cmd)}) exited with code {rc} before it was "
                                   f"ready (port in use?); its output:\n{self.log_text()[-2000:]}")
            # The CLI prints this line after it has bound both ports; checking it (and not only
            # that something answers on the ports) avoids mistaking another server for ours.
            if ("Hosting a web-viewer" in self.log_text() and _port_open(host, self.grpc_port)
                    and _port_open(host, self.web_port)):
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"rerun web viewer not ready after {timeout_s:.0f} s on {self.bind_host} "
                                   f"ports {self.grpc_port}/{self.web_port}; its output:\n{self.log_text()[-2000:]}")
            time.sleep(0.05)

    def stop(self) -> None:
        self._finalizer()  # idempotent: runs _stop_process at most once
        self._log.close()


# --------------------------------------------------------------------------------------------
# The view
# --------------------------------------------------------------------------------------------

def _rgba(c) -> int:
    r, g, b = c[:3]
    a = c[3] if len(c) > 3 else 255
    return (int(r) << 24) | (int(g) << 16) | (int(b) << 8) | int(a)


class _Plot:
    """One frequency plot of one pair (coherence, magnitude or phase): its path and what is on screen."""

    __slots__ = ("path", "kind", "unit", "steps", "color", "box", "extent", "grid_key", "margins")

    def __init__(self, path: str, kind: str, unit: str, steps: Sequence[float], color: tuple, box: tuple,
                 margins: tuple) -> None:
        self.path, self.kind, self.unit, self.steps, self.color, self.box = path, kind, unit, steps, color, box
        self.margins = margins                # (left, right, top, bottom) display units for the labels
        self.extent: tuple | None = None     # (y0, y1, step) plotted
        # box = (x, y, width, height) in the pair view's display units (blueprint.plot_box)
        self.grid_key: tuple | None = None   # what the logged transform and grid were made for


class _PairState:
    """What the view remembers about one pair's plots under ``root`` (``spectra/<out>_<in>``, or
    ``focus``), drawn in a view of ``n_columns`` columns of plots."""

    __slots__ = ("coh", "mag", "phase", "wf_path", "waterfall", "wf_count")

    def __init__(self, root: str, n_columns: int, wf_path: str | None = None) -> None:
        m = plot_margins(n_columns)
        self.coh = _Plot(f"{root}/coherence", "coherence", "γ²", (0.2,), _COH_COLOR, plot_box("coherence", n_columns), m)
        self.mag = _Plot(f"{root}/magnitude_db", "magnitude", "dB", MAG_STEPS_DB, _MAG_COLOR,
                         plot_box("magnitude", n_columns), m)
        self.phase = _Plot(f"{root}/phase_deg", "phase", "deg", PHASE_STEPS_DEG, _PHASE_COLOR,
                           plot_box("phase", n_columns), m)
        self.coh.extent = (0.0, 1.0, 0.2)
        self.wf_path = wf_path
        self.waterfall: np.ndarray | None = None   # (k, n_f) uint8, never mutated once logged
        self.wf_count = 0


class RerunView:
    """Live Rerun view of the sweep monitor (see the module docstring for what is shown).

    Parameters
    ----------
    inputs, outputs : sequence of str
        Signal names; they fix the default blueprint and the pairs (output/input).
    application_id, recording_id : str
        Rerun identifiers (recording_id None: a random one).
    save_path : path or None
        Write an ``.rrd`` file (with the default blueprint). Finalised by :meth:`close`.
    spawn : bool
        Start the desktop viewer (``rr.spawn``) on ``grpc_port`` and stream to it. Needs a display.
    serve : bool
        Start the bundled ``rerun`` CLI serving the web viewer on ``bind_host:web_port`` and a gRPC
        proxy on ``bind_host:grpc_port``; :attr:`web_url` is the address to open. Not together
        with ``spawn`` (both would use ``grpc_port``; open :attr:`web_url` instead).
    waterfall_rows : int
        Estimates kept in each coherence waterfall (0: no waterfall).
    waterfall_every : int
        Re-log the waterfalls every k-th estimate (rows are still added on every estimate).
    flush_timeout_s : float
        Upper bound for :meth:`flush` (an unreachable gRPC sink must not hang shutdown).
    test_point_history : int
        Closed test points kept in the test-point document (the oldest drop out).

    With no sink at all the data goes to an in-memory recording, :attr:`memory`
    (``rr.MemoryRecording``; drain it or it grows).
    """

    def __init__(self, inputs: Sequence[str], outputs: Sequence[str], *, application_id: str = "livesweep",
                 recording_id: str | None = None, save_path: str | os.PathLike | None = None, spawn: bool = False,
                 serve: bool = False, bind_host: str = "127.0.0.1", grpc_port: int = 9876, web_port: int = 9090,
                 waterfall_rows: int = 30, waterfall_every: int = 1, flush_timeout_s: float = 10.0,
                 test_point_history: int = 50) -> None:
        self.inputs, self.outputs = list(inputs), list(outputs)
        check_names(self.inputs, self.outputs)
        if spawn and serve:
            raise ValueError("spawn=True and serve=True both use grpc_port; use serve=True and open web_url")
        if waterfall_rows < 0 or waterfall_every < 1:
            raise ValueError(f"waterfall_rows must be >= 0 and waterfall_every >= 1, got "
                             f"{waterfall_rows} and {waterfall_every}")
        self.waterfall_rows, self.waterfall_every = int(waterfall_rows), int(waterfall_every)
        self.flush_timeout_s = float(flush_timeout_s)
        self.test_point_history = max(0, int(test_point_history))
        self.blueprint = default_blueprint(self.inputs, self.outputs)
        self.save_path = None if save_path is None else Path(save_path)
        self.web_url: str | None = None
        self.grpc_url: str | None = None
        self.memory = None
        self._server: _WebViewerServer | None = None
        self._lock = threading.RLock()
        self._closed = False
        self._series_labels: dict[str, str] = {}
        self._pairs: dict[tuple[str, str], _PairState] = {}
        self._grid_cache: tuple[bytes, dict] | None = None
        self._sweep_inputs: set[str] = set()
        self._test_points: dict[tuple, tuple[int, dict]] = {}   # (start_s, swept_input) -> (number, record)
        self._n_test_points = 0
        self._epoch: bool | None = None       # flight_time as a UNIX timestamp (decided by the first time)
        self._focus: _PairState | None = None  # the swept pair of the test point (focus/)
        self._early_alerts: list = []          # alerts before any flight time: logged at the first one
        self._band_named = False
        self._status: dict | None = None              # the last estimate's status table (re-shown on a verdict change)

        self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self.rec.set_log_time_enabled(False)   # flight_time is the only timeline: replay == live
        self.rec.set_log_tick_enabled(False)

        sinks = []
        try:
            if self.save_path is not None:
                self.save_path.parent.mkdir(parents=True, exist_ok=True)
                sinks.append(rr.FileSink(str(self.save_path)))
            if serve:
                self._server = _WebViewerServer(bind_host, grpc_port, web_port)
                self.grpc_url, self.web_url = self._server.grpc_url, self._server.web_url
                sinks.append(rr.GrpcSink(self.grpc_url))
                log.info("Rerun web viewer at %s (gRPC %s)", self.web_url, self.grpc_url)
                print(serve_banner(bind_host, web_port, grpc_port, self.web_url), file=sys.stderr, flush=True)
            if spawn:
                self.rec.spawn(port=int(grpc_port), connect=False, hide_welcome_screen=True)
                self.grpc_url = f"rerun+http://127.0.0.1:{int(grpc_port)}/proxy"
                sinks.append(rr.GrpcSink(self.grpc_url))
            if sinks:
                self.rec.set_sinks(*sinks, default_blueprint=self.blueprint)
            else:
                self.memory = self.rec.memory_recording()
                self.rec.send_blueprint(self.blueprint)
        except BaseException:
            if self._server is not None:
                self._server.stop()
            raise

        # Component descriptors for the fast path (building these archetypes also pays Rerun's
        # one-off lazy initialisation, ~100 ms, here instead of in the first estimate).
        d = _descriptors(rr.LineStrips2D([[[0.0, 0.0], [1.0, 1.0]]], colors=[[1, 2, 3]], radii=[1.0]))
        self._d_strips, self._d_strip_colors, self._d_strip_radii = (
            d["LineStrips2D:strips"], d["LineStrips2D:colors"], d["LineStrips2D:radii"])
        d = _descriptors(rr.Points2D([[0.0, 0.0]], colors=[[1, 2, 3]]))
        self._d_points, self._d_point_colors = d["Points2D:positions"], d["Points2D:colors"]
        d = _descriptors(rr.DynamicArchetype("Coherence", components={"values": np.zeros(1), "kind": "ordinary"}))
        self._d_coh_values, self._d_coh_kind = d["Coherence:values"], d["Coherence:kind"]
        self._d_tensor = _descriptors(rr.Tensor(np.zeros((1, 1), np.uint8)))["Tensor:data"]
        self._d_scalars = _descriptors(rr.Scalars([0.0]))["Scalars:scalars"]

        for name in self.inputs:
            self._ensure_series(telemetry_path("input", name), name)
        for name in self.outputs:
            self._ensure_series(telemetry_path("output", name), name)
        self._fraction_pairs: list = []        # the pairs of the adequacy rows (series names logged for them)
        for o in self.outputs:
            for i in self.inputs:
                self._pair(o, i)

    # ---------------------------------------------------------------- helpers

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("RerunView is closed")

    def _ensure_series(self, path: str, label: str) -> None:
        """The series' name in the legend (static), logged again only when it changes."""
        if self._series_labels.get(path) != label:
            self.rec.log(path, rr.SeriesLines(names=label), static=True)
            self._series_labels[path] = label

    def _pair(self, o: str, i: str) -> _PairState:
        st = self._pairs.get((o, i))
        if st is None:
            st = self._pairs[(o, i)] = self._new_pair(pair_path(o, i), len(self.inputs), waterfall_path(o, i))
        return st

    def _new_pair(self, root: str, n_columns: int, wf_path: str | None) -> _PairState:
        st = _PairState(root, n_columns, wf_path if self.waterfall_rows else None)
        for p in (st.coh, st.mag, st.phase):
            self.rec.log(p.path, rr.LineStrips2D.from_fields(draw_order=20.0), static=True)
        self.rec.log(st.coh.path, rr.Points2D.from_fields(radii=rr.Radius.ui_points(2.0), draw_order=21.0),
                     static=True)
        if st.wf_path is not None:
            self.rec.log(st.wf_path, rr.Tensor.from_fields(value_range=(0.0, 100.0)), static=True)
        return st

    def _grid_batches(self, omega: np.ndarray) -> dict:
        """Per-frequency-grid values, built once and shared by every pair and update."""
        key = omega.tobytes()
        if self._grid_cache is not None and self._grid_cache[0] == key:
            return self._grid_cache[1]
        x0, x1 = frequency_extent(omega)
        g = {
            "key": key,
            "logw": np.log10(omega),
            "x": (x0, x1),
            "dims": ("estimate (newest last)",
                     f"frequency bin (0: {omega[0]:.3g} ... {omega.size - 1}: {omega[-1]:.3g} rad/s)"),
        }
        self._grid_cache = (key, g)
        return g

    def _log_frame(self, plot: _Plot, x_range: tuple[float, float], label: str) -> None:
        """The plot's display transform and grid, logged at the current time when they change.

        The transform maps the data box [x0, x1] x [y0, y1] (log10 rad/s, value) onto the plot box
        (:func:`plot_box`, y down); the grid (a child entity, so under the same transform) has a
        line at every 1-2-5 frequency and every value step, frequency labels under the box,
        value labels left of it and the axis name above them.
        """
        y0, y1, step = plot.extent
        key = (x_range, plot.extent, label)
        if key == plot.grid_key:
            return
        plot.grid_key = key
        x0, x1 = x_range
        bx, by, w, h = plot.box
        sx, sy = w / (x1 - x0), h / (y1 - y0)
        self.rec.log(plot.path, rr.Transform3D(translation=[bx - x0 * sx, by + y1 * sy, 0.0], scale=[sx, -sy, 1.0]))
        left, _, top, bottom = plot.margins
        below, beside, above = y0 - 0.4 * bottom / sy, x0 - 0.5 * left / sx, y1 + 0.6 * top / sy
        major, minor, pts, labels = [], [], [], []
        ticks = log_ticks(x0, x1)
        for k, (x, is_decade) in enumerate(ticks):
            (major if is_decade else minor).append([[x, y0], [x, y1]])
            pts.append([x, below])
            labels.append(tick_label(10.0 ** x) + (" rad/s" if k == len(ticks) - 1 else ""))
        n = int(round((y1 - y0) / step))
        for k in range(n + 1):
            yy = y0 + k * step
            (major if k in (0, n) or plot.kind != "coherence" else minor).append([[x0, yy], [x1, yy]])
            pts.append([beside, yy])
            labels.append(tick_label(yy))
        pts.append([beside, above])
        labels.append(label)
        self.rec.log(f"{plot.path}/grid",
                     rr.LineStrips2D(major + minor,
                                     colors=[_GRID_COLOR] * len(major) + [_GRID_MINOR_COLOR] * len(minor),
                                     radii=rr.Radius.ui_points(0.5), draw_order=5.0),
                     rr.Points2D(pts, labels=labels, show_labels=True, radii=rr.Radius.ui_points(0.5),
                                 colors=[_GRID_COLOR], draw_order=6.0))
        if plot.kind == "coherence":
            self.rec.log(f"{plot.path}/threshold",
                         rr.LineStrips2D([[[x0, MIN_COHERENCE], [x1, MIN_COHERENCE]]], colors=[_THRESHOLD_COLOR],
                                         radii=rr.Radius.ui_points(1.0), labels=[f"γ² = {MIN_COHERENCE:g}"],
                                         show_labels=False, draw_order=15.0))

    def _log_curve(self, plot: _Plot, logw: np.ndarray, y: np.ndarray, coherent: np.ndarray,
                   extra: list | None = None) -> None:
        """One curve: coherent stretches in the plot's colour, masked ones grey and thin (see
        :func:`masked_runs`; a masked point outside the plotted range is not drawn)."""
        y0, y1, _ = plot.extent
        runs = masked_runs(y, coherent, (y0, y1))
        xy = np.empty((y.size, 2), np.float32)
        xy[:, 0] = logw
        xy[:, 1] = y
        strips = [xy[a:b] for a, b, _ in runs]
        good = np.array([ok for _, _, ok in runs], bool)
        colors = np.where(good, _rgba(plot.color), _rgba(_MASKED_COLOR)).astype(np.uint32)
        radii = np.where(good, _CURVE_RADIUS, _MASKED_RADIUS).astype(np.float32)
        DCB = rr.DescribedComponentBatch
        batches = [DCB(_Arrow(_strips_array(strips)), self._d_strips),
                   DCB(_Arrow(pa.array(colors)), self._d_strip_colors),
                   DCB(_Arrow(pa.array(radii)), self._d_strip_radii)]
        self.rec.log(plot.path, batches + (extra or []))

    def _is_epoch(self, t_s: float) -> bool:
        """Whether flight_time is a timestamp: decided by the first time logged, kept after (a
        timeline has one type)."""
        if self._epoch is None:
            self._epoch = abs(float(t_s)) >= EPOCH_MIN_S
        return self._epoch

    def _set_time(self, t_s: float) -> None:
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"flight time must be finite, got {t_s!r}")
        if self._is_epoch(t):
            self.rec.set_time(TIMELINE, timestamp=np.datetime64(int(_ns(t)), "ns"))
        else:
            self.rec.set_time(TIMELINE, duration=np.timedelta64(int(_ns(t)), "ns"))
        if self._early_alerts:
            early, self._early_alerts = self._early_alerts, []
            for kind, message in early:
                self.rec.log(ALERTS_PATH, rr.TextLog(f"[{kind}] {message}", level=rr.TextLogLevel.WARN))

    # ---------------------------------------------------------------- public API

    def log_timeseries(self, t_s: np.ndarray, names: Sequence[str], values: np.ndarray,
                       kinds: Sequence[str], units: Sequence[str | None] | None = None) -> None:
        """One block of samples: ``values[k]`` is signal ``names[k]`` at the flight times ``t_s`` [s].

        Parameters
        ----------
        t_s : array (n,)
            Flight time [s], finite.
        names : sequence of str
        values : array (len(names), n)
            Samples in each signal's own unit.
        kinds : sequence of str
            ``"input"`` or ``"output"`` per name.
        units : sequence of str or None, optional
            Unit per name (``"deg"``, ``"deg/s"``, ``"ft/s^2"``); the series is named
            ``"<name> [<unit>]"`` in the legend. None (or an empty unit): the bare name.
        """
        with self._lock:
            self._check_open()
            t = np.asarray(t_s, dtype=np.float64)
            v = np.array(values, dtype=np.float64, copy=True)   # private copy: pyarrow wraps it
            names, kinds = list(names), list(kinds)
            units = [None] * len(names) if units is None else list(units)
            if v.ndim == 1 and len(names) == 1:
                v = v[None, :]
            if t.ndim != 1:
                raise ValueError(f"t_s must be 1-D, got shape {t.shape}")
            if len(kinds) != len(names) or len(units) != len(names) or v.shape != (len(names), t.size):
                raise ValueError(f"values must have shape (len(names), len(t_s)) = ({len(names)}, {t.size}) with one "
                                 f"kind and one unit per name; got values {v.shape}, {len(names)} names, "
                                 f"{len(kinds)} kinds, {len(units)} units")
            paths = [telemetry_path(kind, name) for name, kind in zip(names, kinds)]
            for path, name, unit in zip(paths, names, units):
                self._ensure_series(path, series_label(name, unit))
            if t.size == 0:
                return
            if not np.all(np.isfinite(t)):
                bad = int(np.flatnonzero(~np.isfinite(t))[0])
                raise ValueError(f"t_s[{bad}] = {t[bad]!r} is not a finite flight time")
            times = (rr.TimeColumn(TIMELINE, timestamp=_ns(t).astype("datetime64[ns]")) if self._is_epoch(t[0])
                     else rr.TimeColumn(TIMELINE, duration=_ns(t).astype("timedelta64[ns]")))
            for path, row in zip(paths, v):
                col = rr.ComponentColumn(self._d_scalars, _Arrow(pa.array(row)))
                self.rec.send_columns(path, indexes=[times], columns=[col])

    def log_estimate(self, t_s: float, omega: np.ndarray, outputs: Sequence[str], inputs: Sequence[str],
                     coherence: np.ndarray, magnitude_db: np.ndarray, phase_deg: np.ndarray,
                     adequacy_rows: Sequence[dict], verdict: str, reasons: Sequence[str], *,
                     coherence_kind: str = "ordinary", sweep: dict | None = None, spectra: bool = True,
                     band_rad_s: tuple | None = None, lag_s: float | None = None) -> None:
        """One spectral estimate at flight time ``t_s`` [s].

        Parameters
        ----------
        t_s : float
            Flight time of the estimate [s].
        omega : array (n_f,)
            Frequency grid [rad/s], > 0.
        outputs, inputs : sequence of str
        coherence, magnitude_db, phase_deg : arrays (n_out, n_in, n_f)
            gamma^2 (the one the verdict judged), |H| [dB] and phase [deg]. The phase is drawn
            unwrapped along frequency and moved by whole turns so its value at the lowest
            coherent frequency lies in (-180, 180] (:func:`reference_phase`).
        adequacy_rows : sequence of dict
            ``{"output", "input", "band": (lo, hi) [rad/s] or None, "fraction": 0..1}`` per pair.
        verdict : str
        reasons : sequence of str
        coherence_kind : str
            ``"ordinary"`` or ``"partial"`` (MISO-conditioned): which coherence ``coherence`` is;
            shown in each coherence plot and in the status text.
        sweep : dict, optional
            ``{input: (omega [rad/s] or None, time remaining [s] or None)}``: the sweep frequency
            and the sweep time still needed to reach the band's top, logged as scalars (NaN when
            None) and written in the status text.
        spectra : bool
            Draw every pair's frequency plots and waterfall (the "All pairs" tab); False: only the
            status, fractions and sweep (a web viewer that must keep up gets the heavy part less often).
        band_rad_s : (float, float), optional
            The band the running test point is judged over [rad/s], drawn with the sweep frequency
            (NaN when None).
        lag_s : float, optional
            How far behind the link this estimate is [s] (receive time of the newest frame in it to
            now), said in the status text.
        """
        with self._lock:
            self._check_open()
            coherence_kind_text(coherence_kind)      # ValueError for anything but ordinary/partial
            outputs, inputs = list(outputs), list(inputs)
            w = np.array(omega, dtype=np.float64, copy=True).ravel()
            if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise ValueError("omega must be a non-empty 1-D array of finite frequencies > 0 rad/s")
            shape = (len(outputs), len(inputs), w.size)
            arrays = []
            for what, a in (("coherence", coherence), ("magnitude_db", magnitude_db), ("phase_deg", phase_deg)):
                a = np.array(a, dtype=np.float64, copy=True)
                if a.shape != shape:
                    raise ValueError(f"{what} must have shape (n_outputs, n_inputs, n_f) = {shape}, got {a.shape}")
                arrays.append(a)
            sweep = {str(k): _sweep_pair(k, v) for k, v in (sweep or {}).items()}
            self._set_time(t_s)
            rec = self.rec
            if spectra:
                self._draw_pairs(w, outputs, inputs, *arrays, coherence_kind)
            pairs = [(r.get("output"), r.get("input")) for r in adequacy_rows]
            if pairs and pairs != self._fraction_pairs:
                self._fraction_pairs = pairs
                rec.log(FRACTION_PATH, rr.SeriesLines(names=[pair_label(o, i) for o, i in pairs]), static=True)
            if pairs:
                frac = np.array([np.nan if r.get("fraction") is None else float(r["fraction"])
                                 for r in adequacy_rows])
                rec.log(FRACTION_PATH, rr.Scalars(frac))
            for name, (f_rad_s, remaining_s) in sweep.items():
                if name not in self._sweep_inputs:
                    self._sweep_inputs.add(name)
                    rec.log(sweep_frequency_path(name), rr.SeriesLines(names=f"{name} [rad/s]"), static=True)
                    rec.log(time_remaining_path(name), rr.SeriesLines(names=f"{name} [s]"), static=True)
                rec.log(sweep_frequency_path(name), rr.Scalars(np.nan if f_rad_s is None else f_rad_s))
                rec.log(time_remaining_path(name), rr.Scalars(np.nan if remaining_s is None else remaining_s))
            if not self._band_named:
                self._band_named = True
                for path, name in zip(BAND_EDGE_PATHS, ("band judged: bottom", "band judged: top")):
                    rec.log(path, rr.SeriesLines(names=name, colors=[_BAND_EDGE_COLOR], widths=[2.0]), static=True)
            for path, edge in zip(BAND_EDGE_PATHS, band_rad_s or (None, None)):
                rec.log(path, rr.Scalars(np.nan if edge is None else float(edge)))
            self._status = {"rows": list(adequacy_rows), "coherence_kind": coherence_kind, "sweep": sweep}
            rec.log(ADEQUACY_PATH, rr.TextDocument(
                adequacy_markdown(t_s, adequacy_rows, verdict, reasons, coherence_kind=coherence_kind, sweep=sweep,
                                  lag_s=lag_s),
                media_type=rr.MediaType.MARKDOWN))

    def log_verdict(self, t_s: float, verdict: str, reasons: Sequence[str]) -> None:
        """A change of the operator's verdict between estimates (a test point closed after the last
        samples): the status document shows it at once, with the last estimate's table."""
        with self._lock:
            self._check_open()
            if self._status is None or t_s is None:      # before the first estimate: it will show the verdict
                return
            self._set_time(t_s)
            st = self._status
            sweep = {k: (None, None) for k in (st["sweep"] or {})}     # no sweep is tracked without samples
            self.rec.log(ADEQUACY_PATH, rr.TextDocument(
                adequacy_markdown(t_s, st["rows"], verdict, reasons, coherence_kind=st["coherence_kind"],
                                  sweep=sweep), media_type=rr.MediaType.MARKDOWN))

    def _draw_pairs(self, w: np.ndarray, outputs: list, inputs: list, coh: np.ndarray, mag: np.ndarray,
                    pha: np.ndarray, coherence_kind: str) -> None:
        """Every pair's frequency plots and waterfall (the "All pairs" tab)."""
        g = self._grid_batches(w)
        coherent = np.isfinite(coh) & (coh >= MIN_COHERENCE)
        pha = reference_phase(pha, coherent)
        wf_pct = None
        if self.waterfall_rows:
            wf_pct = np.clip(np.rint(np.nan_to_num(coh, nan=0.0) * 100.0), 0, 100).astype(np.uint8)
        for io, o in enumerate(outputs):
            for ii, i in enumerate(inputs):
                st = self._pair(o, i)
                self._draw_pair(st, g, coh[io, ii], mag[io, ii], pha[io, ii], coherent[io, ii], coherence_kind)
                if wf_pct is not None:
                    row = wf_pct[io, ii][None, :]
                    old = st.waterfall
                    if old is None or old.shape[1] != w.size:
                        new = row.copy()
                    else:
                        keep = old[len(old) - (self.waterfall_rows - 1):] if self.waterfall_rows > 1 else old[:0]
                        new = np.concatenate([keep, row])
                    st.waterfall = new   # a new array every time: the logged one is never mutated
                    st.wf_count += 1
                    if st.wf_count == 1 or st.wf_count % self.waterfall_every == 0:
                        self.rec.log(st.wf_path, [rr.DescribedComponentBatch(_Arrow(_tensor_array(new, g["dims"])),
                                                                              self._d_tensor)])

    def _draw_pair(self, st: _PairState, g: dict, c: np.ndarray, mag: np.ndarray, pha: np.ndarray,
                   ok: np.ndarray, coherence_kind: str) -> None:
        """One pair's three plots on the frequency grid ``g`` (:meth:`_grid_batches`); ``pha`` already
        referenced (:func:`reference_phase`), ``ok`` where gamma^2 >= the threshold."""
        DCB = rr.DescribedComponentBatch
        logw, x_range = g["logw"], g["x"]
        fin = np.isfinite(c)
        pos = np.empty((int(fin.sum()), 2), np.float32)
        pos[:, 0] = logw[fin]
        pos[:, 1] = c[fin]
        pcol = np.where(ok[fin], _rgba(_COH_COLOR), _rgba(_MASKED_COLOR)).astype(np.uint32)
        points = pa.FixedSizeListArray.from_arrays(pa.array(pos.ravel()), type=_POINT_T)
        self._log_frame(st.coh, x_range, "γ² " + coherence_kind)
        self._log_curve(st.coh, logw, c, ok, [
            DCB(_Arrow(points), self._d_points), DCB(_Arrow(pa.array(pcol)), self._d_point_colors),
            DCB(_Arrow(pa.array(c)), self._d_coh_values),
            DCB(_Arrow(pa.array([coherence_kind], pa.string())), self._d_coh_kind)])
        for plot, y, label in ((st.mag, mag, "|H| dB"), (st.phase, pha, "phase deg")):
            lo, hi = _curve_range(y, ok, turns=plot is st.phase)
            plot.extent = value_extent(plot.extent, lo, hi, plot.steps)
            if plot.extent is None:
                continue      # nothing finite yet: nothing to draw
            self._log_frame(plot, x_range, label)
            self._log_curve(plot, logw, y, ok)

    def log_focus(self, t_s: float, response, title: str) -> None:
        """The swept pair of a test point as its verdict judged it, over the judged band (the "Test
        point" tab's plots): ``response`` a :class:`~livesweep.spectral.response.FrequencyResponse`
        (its coherence, |H| and phase), ``title`` what it is ("TP 2 p/roll: GO so far")."""
        with self._lock:
            self._check_open()
            w = np.asarray(response.omega, float)
            if w.size < 2:
                return
            if self._focus is None:
                self._focus = self._new_pair(FOCUS_PATH, 1, None)
            self._set_time(t_s)
            c = np.asarray(response.coherence, float)
            H = np.asarray(response.H, complex)
            ok = np.isfinite(c) & (c >= MIN_COHERENCE)
            with np.errstate(divide="ignore", invalid="ignore"):
                mag = 20.0 * np.log10(np.abs(H))
            pha = reference_phase(np.degrees(np.angle(H)), ok)
            kind = "partial" if getattr(response, "conditioned", False) else "ordinary"
            x0, x1 = frequency_extent(w)
            self._draw_pair(self._focus, {"logw": np.log10(w), "x": (x0, x1)}, c, mag, pha, ok, kind)
            _, _, top, _ = self._focus.coh.margins
            bx, by, bw, _ = self._focus.coh.box          # centred above the coherence plot
            self.rec.log(f"{FOCUS_PATH}/title", rr.Points2D([[bx + 0.5 * bw, by - 0.7 * top]], labels=[title],
                                                            show_labels=True, radii=rr.Radius.ui_points(0.5),
                                                            colors=[_TITLE_COLOR]))

    def log_test_point(self, t_s: float, tp: dict) -> None:
        """A test point opened, was judged, or closed: the test-point document at flight time ``t_s`` [s].

        Parameters
        ----------
        t_s : float
            Flight time [s].
        tp : dict
            The monitor's ``/livesweep/test_point`` record: ``{"state": "open"|"closed", "start_s",
            "end_s" (None while open), "source", "swept_input", "verdict", "pairs": [{"output",
            "input", "adequate_fraction", "band_rad_s": [lo, hi] or None, "coherence":
            "ordinary"|"partial"}], "missing": [str, ...]}``.

        The document (``status/test_points``, markdown) lists the open test point first, then the
        others newest first, each with its table (pair, coherence kind, adequate band, fraction,
        verdict, what is still missing); a record with the same start and swept input replaces
        the earlier one, so each test point appears once. At most ``test_point_history`` closed
        ones are kept.
        """
        with self._lock:
            self._check_open()
            if not isinstance(tp, dict):
                raise TypeError(f"tp must be a dict (the /livesweep/test_point record), got {type(tp).__name__}")
            key = tp.get("start_s")                  # one test point, whatever its record learns later
            if tp.get("state") in ("ignored", "superseded"):
                self._test_points.pop(key, None)     # not a test point after all: no phantom stays
            else:
                if key in self._test_points:
                    number = self._test_points[key][0]
                else:
                    self._n_test_points += 1
                    number = self._n_test_points
                self._test_points[key] = (number, dict(tp))
            closed = [k for k, (_, r) in self._test_points.items() if r.get("state") != "open"]
            for k in closed[:max(0, len(closed) - self.test_point_history)]:
                del self._test_points[k]
            entries = sorted(self._test_points.values(),
                             key=lambda e: (e[1].get("state") != "open", -e[0]))
            self._set_time(t_s)
            self.rec.log(TEST_POINTS_PATH, rr.TextDocument(markdown_test_points(entries, t_s),
                                                           media_type=rr.MediaType.MARKDOWN))

    def log_alerts(self, t_s: float | None, alerts: Sequence[tuple[str, str]]) -> None:
        """Alerts as WARN text-log lines ``"[kind] message"`` at flight time ``t_s``; alerts before
        any data (``t_s`` None) wait for the first flight time (a placeholder time would decide the
        timeline's type wrongly: a duration where the data's clock is the UTC one)."""
        with self._lock:
            self._check_open()
            alerts = list(alerts)
            if not alerts:
                return
            if t_s is None or not math.isfinite(float(t_s)):
                self._early_alerts.extend(alerts)
                return
            self._set_time(t_s)
            for kind, message in alerts:
                self.rec.log(ALERTS_PATH, rr.TextLog(f"[{kind}] {message}", level=rr.TextLogLevel.WARN))

    def flush(self) -> None:
        """Block until everything logged so far reached the sinks (at most ``flush_timeout_s``)."""
        with self._lock:
            if not self._closed:
                self.rec.flush(timeout_sec=self.flush_timeout_s)

    def close(self) -> None:
        """Flush, disconnect (finalises the .rrd footer) and stop the web-viewer child. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self.rec.flush(timeout_sec=self.flush_timeout_s)
                self.rec.disconnect()
            finally:
                if self._server is not None:
                    self._server.stop()

    @property
    def server_pid(self) -> int | None:
        """Process id of the web-viewer child (serve=True), else None."""
        return None if self._server is None else self._server.proc.pid

    def __enter__(self) -> RerunView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def series_label(name: str, unit: str | None) -> str:
    """A time series' legend name: ``"da [deg]"``, or the bare name without a unit."""
    return f"{name} [{unit}]" if unit else str(name)


def _sweep_pair(name, v) -> tuple[float | None, float | None]:
    try:
        f, rem = v
    except (TypeError, ValueError):
        raise ValueError(f"sweep[{name!r}] must be (omega_rad_s or None, time_remaining_s or None), got {v!r}") from None
    f = None if f is None or not math.isfinite(float(f)) else float(f)
    rem = None if rem is None or not math.isfinite(float(rem)) else float(rem)
    return f, rem


def _curve_range(y: np.ndarray, coherent: np.ndarray, *, turns: bool = False) -> tuple[float, float]:
    """The range one curve needs: its coherent finite values, or all its finite values when fewer
    than two are coherent; (inf, -inf) when nothing is finite. With ``turns`` (a phase) of a pair
    coherent over less than half its points, at most two turns about the median of those values:
    the chance-coherent islands of an unexcited pair, which walk through many turns, must not set
    an axis of thousands of degrees (a response coherent over the band keeps all its turns)."""
    fin = np.isfinite(y)
    use = fin & coherent
    if use.sum() < 2:
        use = fin
    if not use.any():
        return math.inf, -math.inf
    v = y[use]
    lo, hi = float(v.min()), float(v.max())
    if turns and hi - lo > 720.0 and (fin & coherent).sum() < 0.5 * fin.sum():
        mid = float(np.median(v))
        lo, hi = max(lo, mid - 360.0), min(hi, mid + 360.0)
    return lo, hi
