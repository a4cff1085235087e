"""The live Rerun view of the sweep monitor.

What the engineer sees, and how each item is represented (entity paths: :mod:`.blueprint`):

* **Time series** of inputs and outputs: ``rr.Scalars`` per signal, sent in blocks with
  ``send_columns`` on the ``flight_time`` timeline (a duration; ``round(t_s * 1e9)`` ns).
* **Coherence** per pair: ``rr.BarChart`` with ``abscissa = omega [rad/s]`` and bar ``widths`` from
  the grid spacing (Rerun's default width is 1 rad/s, which would smear a log grid). The bar
  chart view has real axes and hover, so ω and γ² are read directly.
* **Magnitude [dB] and phase [deg]** per pair: ``rr.LineStrips2D`` whose points are
  ``(log10 omega, value)``, exactly the numbers the estimator produced (float32). Rerun's 2-D
  view has y pointing down and equal axis scales, so a *static* ``rr.Transform3D`` on the entity
  scales the display (1 decade = 150 units; 1 dB = 1.5 units; 1 deg = 0.5 unit) and flips y; a
  static grid with labelled decades (rad/s) and dB/deg lines is a child entity, so it gets the
  same transform. The view origin is the pair folder, which is what makes the transform apply.
* **Coherence waterfall** per pair: ``rr.Tensor`` of shape (estimates, frequency bins) holding
  γ² in **percent as uint8** (value range 0..100), the last ``waterfall_rows`` estimates with the
  newest in the last row, shown in a TensorView with the viridis colormap. A tensor (not an
  Image or DepthImage) because the TensorView maps scalars through a colormap with a fixed
  range and names the two axes; an Image would need its own colour conversion and a DepthImage
  would claim metres. uint8 percent keeps the re-logged history small (the exact γ² is in the
  bar chart); see "Costs" below.
* **Adequacy**: a markdown ``rr.TextDocument`` (pair, adequate band, fraction, verdict, plus the
  overall verdict and its reasons) and ``status/adequacy_fraction``, one series per pair.
* **Alerts**: ``rr.TextLog`` at level WARN, text ``"[kind] message"``.

Costs: ``rr.log`` with archetype objects costs ~0.3-1.4 ms per spectral entity (the Python-side
tensor conversion), i.e. >100 ms per update for 48 pairs. The hot path therefore builds the Arrow
arrays itself (``_tensor_array``, ``_strips_array``) and logs them as described component
batches; the grid/abscissa/width batches are built once per frequency grid and reused.

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
    ADEQUACY_PATH, ALERTS_PATH, FRACTION_PATH, TIMELINE, check_names, coherence_path, default_blueprint,
    magnitude_path, pair_label, phase_path, telemetry_path, waterfall_path,
)

__all__ = ["RerunView", "find_rerun_cli", "MAG_DISPLAY_SCALE", "PHASE_DISPLAY_SCALE"]

log = logging.getLogger(__name__)

#: Display transform of the Bode plots: (units per decade of ω, units per dB or deg); y is flipped.
MAG_DISPLAY_SCALE = (150.0, 1.5)
PHASE_DISPLAY_SCALE = (150.0, 0.5)

_MAG_COLOR = (31, 119, 180)
_PHASE_COLOR = (214, 39, 40)
_GRID_COLOR = (128, 128, 128, 110)
_GRID_MINOR_COLOR = (128, 128, 128, 50)


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


def _finite_runs(x: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
    """(n, 2) float32 strips of (x, y), split where y is not finite (a gap, not a zero)."""
    ok = np.isfinite(y) & np.isfinite(x)
    xy = np.column_stack([x, y]).astype(np.float32)
    if ok.all():
        return [xy]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    return [xy[a:b] for a, b in zip(edges[::2], edges[1::2])]


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

def _grid_step(span: float, steps: Sequence[float]) -> float:
    for s in steps:
        if span / s <= 8:
            return s
    return steps[-1] * math.ceil(span / (8 * steps[-1]))


def _round_125(w: float, *, down: bool) -> float:
    """log10 of the nearest 1-2-5 value (..., 0.5, 1, 2, 5, 10, ...) below (down) or above ``w``."""
    d = math.floor(math.log10(w))
    cands = [m * 10.0 ** e for e in (d - 1, d, d + 1) for m in (1, 2, 5)]
    v = max(c for c in cands if c <= w * (1 + 1e-9)) if down else min(c for c in cands if c >= w * (1 - 1e-9))
    return math.log10(v)


def _ticks_125(x0: float, x1: float) -> list[tuple[float, bool]]:
    """(log10 value, is a decade) of the 1-2-5 values in [10^x0, 10^x1]."""
    out = []
    for e in range(math.floor(x0) - 1, math.ceil(x1) + 1):
        for m in (1, 2, 5):
            x = e + math.log10(m)
            if x0 - 1e-9 <= x <= x1 + 1e-9:
                out.append((x, m == 1))
    return out


class _PairState:
    """What the view remembers about one output/input pair."""

    __slots__ = ("coh_path", "mag_path", "phase_path", "wf_path", "grid_key", "waterfall", "wf_count",
                 "mag_extent", "phase_extent")

    def __init__(self, o: str, i: str) -> None:
        self.coh_path, self.mag_path = coherence_path(o, i), magnitude_path(o, i)
        self.phase_path, self.wf_path = phase_path(o, i), waterfall_path(o, i)
        self.grid_key: bytes | None = None         # omega grid whose abscissa/widths were last logged
        self.waterfall: np.ndarray | None = None   # (k, n_f) uint8, never mutated once logged
        self.wf_count = 0
        self.mag_extent: tuple | None = None       # (x0, x1, y0, y1) of the logged grid
        self.phase_extent: tuple | None = None


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

    With no sink at all the data goes to an in-memory recording, :attr:`memory`
    (``rr.MemoryRecording``; drain it or it grows).
    """

    def __init__(self, inputs: Sequence[str], outputs: Sequence[str], *, application_id: str = "livesweep",
                 recording_id: str | None = None, save_path: str | os.PathLike | None = None, spawn: bool = False,
                 serve: bool = False, bind_host: str = "127.0.0.1", grpc_port: int = 9876, web_port: int = 9090,
                 waterfall_rows: int = 30, waterfall_every: int = 1, flush_timeout_s: float = 10.0) -> None:
        self.inputs, self.outputs = list(inputs), list(outputs)
        check_names(self.inputs, self.outputs)
        if spawn and serve:
            raise ValueError("spawn=True and serve=True both use grpc_port; use serve=True and open web_url")
        if waterfall_rows < 0 or waterfall_every < 1:
            raise ValueError(f"waterfall_rows must be >= 0 and waterfall_every >= 1, got "
                             f"{waterfall_rows} and {waterfall_every}")
        self.waterfall_rows, self.waterfall_every = int(waterfall_rows), int(waterfall_every)
        self.flush_timeout_s = float(flush_timeout_s)
        self.blueprint = default_blueprint(self.inputs, self.outputs)
        self.save_path = None if save_path is None else Path(save_path)
        self.web_url: str | None = None
        self.grpc_url: str | None = None
        self.memory = None
        self._server: _WebViewerServer | None = None
        self._lock = threading.RLock()
        self._closed = False
        self._known_series: set[str] = set()
        self._pairs: dict[tuple[str, str], _PairState] = {}
        self._grid_cache: tuple[bytes, dict] | None = None

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
                print(f"livesweep: Rerun web viewer at {self.web_url}", file=sys.stderr, flush=True)
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
        d = _descriptors(rr.BarChart([0.0], abscissa=[0.0], widths=[1.0]))
        self._d_bar_values = d["BarChart:values"]
        self._d_strips = _descriptors(rr.LineStrips2D([[[0.0, 0.0], [1.0, 1.0]]]))["LineStrips2D:strips"]
        self._d_tensor = _descriptors(rr.Tensor(np.zeros((1, 1), np.uint8)))["Tensor:data"]
        self._d_scalars = _descriptors(rr.Scalars([0.0]))["Scalars:scalars"]

        for name in self.inputs:
            self._ensure_series(telemetry_path("input", name), name)
        for name in self.outputs:
            self._ensure_series(telemetry_path("output", name), name)
        self._fraction_pairs = [(o, i) for o in self.outputs for i in self.inputs]
        if self._fraction_pairs:
            self.rec.log(FRACTION_PATH, rr.SeriesLines(names=[pair_label(o, i) for o, i in self._fraction_pairs]),
                         static=True)
        for o in self.outputs:
            for i in self.inputs:
                self._pair(o, i)

    # ---------------------------------------------------------------- helpers

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("RerunView is closed")

    def _ensure_series(self, path: str, name: str) -> None:
        if path not in self._known_series:
            self.rec.log(path, rr.SeriesLines(names=name), static=True)
            self._known_series.add(path)

    def _pair(self, o: str, i: str) -> _PairState:
        st = self._pairs.get((o, i))
        if st is None:
            st = self._pairs[(o, i)] = _PairState(o, i)
            for path, (sx, sy), color in ((st.mag_path, MAG_DISPLAY_SCALE, _MAG_COLOR),
                                          (st.phase_path, PHASE_DISPLAY_SCALE, _PHASE_COLOR)):
                self.rec.log(path, rr.Transform3D(scale=[sx, -sy, 1.0]), static=True)
                self.rec.log(path, rr.LineStrips2D.from_fields(colors=[color], radii=rr.Radius.ui_points(1.5),
                                                               draw_order=20.0), static=True)
            if self.waterfall_rows:
                self.rec.log(st.wf_path, rr.Tensor.from_fields(value_range=(0.0, 100.0)), static=True)
        return st

    def _grid_batches(self, omega: np.ndarray) -> dict:
        """Per-frequency-grid arrays, built once and shared by every pair and update."""
        key = omega.tobytes()
        if self._grid_cache is not None and self._grid_cache[0] == key:
            return self._grid_cache[1]
        widths = (0.9 * np.gradient(omega)) if omega.size > 1 else np.ones(1)
        bar = rr.BarChart(np.zeros(omega.size), abscissa=omega, widths=widths.astype(np.float32))
        g = {
            "key": key,
            "bar": [b for b in bar.as_component_batches()
                    if b.component_descriptor().component in ("BarChart:abscissa", "BarChart:widths")],
            "logw": np.log10(omega),
            "x_lo": _round_125(float(omega.min()), down=True), "x_hi": _round_125(float(omega.max()), down=False),
            "dims": ("estimate (newest last)",
                     f"frequency bin (0: {omega[0]:.3g} ... {omega.size - 1}: {omega[-1]:.3g} rad/s)"),
        }
        self._grid_cache = (key, g)
        return g

    def _log_grid(self, path: str, extent_old: tuple | None, g: dict, y_min: float, y_max: float, unit: str,
                  steps: Sequence[float]) -> tuple | None:
        """Static grid + labels under ``path``; re-logged only when the plotted range grows.

        x spans the 1-2-5 values around the frequency grid (lines at 1, 2, 5 x 10^k rad/s), y the
        multiples of a step (5/10/20 dB, 15/30/45/90 deg) around the data. Frequency labels sit on
        the bottom line, value labels left of the left line (none at the shared corner).
        """
        if not (math.isfinite(y_min) and math.isfinite(y_max)):
            return extent_old
        x0, x1 = g["x_lo"], g["x_hi"]
        y0, y1 = y_min, y_max
        if extent_old is not None:
            if x0 >= extent_old[0] and x1 <= extent_old[1] and y0 >= extent_old[2] and y1 <= extent_old[3]:
                return extent_old   # the common case: nothing to do
            x0, x1 = min(x0, extent_old[0]), max(x1, extent_old[1])
            y0, y1 = min(y0, extent_old[2]), max(y1, extent_old[3])
        step = _grid_step(max(y1 - y0, 1e-9), steps)
        y0, y1 = step * math.floor(y0 / step), step * math.ceil(y1 / step)
        if y1 <= y0:
            y1 = y0 + step
        ext = (x0, x1, y0, y1)
        if ext == extent_old:
            return ext
        major, minor, pts, labels = [], [], [], []
        ticks = _ticks_125(x0, x1)
        for k, (x, is_decade) in enumerate(ticks):
            (major if is_decade else minor).append([[x, y0], [x, y1]])
            if is_decade or k in (0, len(ticks) - 1):
                pts.append([x, y0 - 0.5 * step])
                labels.append(f"{10.0 ** x:.3g}" + (" rad/s" if k == len(ticks) - 1 else ""))
        n = int(round((y1 - y0) / step))
        for k in range(n + 1):
            yy = y0 + k * step
            major.append([[x0, yy], [x1, yy]])
            if k > 0:
                pts.append([x0 - 0.12 * (x1 - x0), yy])
                labels.append(f"{yy:g} {unit}")
        self.rec.log(f"{path}/grid",
                     rr.LineStrips2D(major + minor,
                                     colors=[_GRID_COLOR] * len(major) + [_GRID_MINOR_COLOR] * len(minor),
                                     radii=rr.Radius.ui_points(0.5), draw_order=5.0),
                     rr.Points2D(pts, labels=labels, show_labels=True, radii=rr.Radius.ui_points(1.0),
                                 colors=[_GRID_COLOR], draw_order=6.0),
                     static=True)
        return ext

    def _set_time(self, t_s: float) -> None:
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"flight time must be finite, got {t_s!r}")
        self.rec.set_time(TIMELINE, duration=np.timedelta64(int(_ns(t)), "ns"))

    # ---------------------------------------------------------------- public API

    def log_timeseries(self, t_s: np.ndarray, names: Sequence[str], values: np.ndarray,
                       kinds: Sequence[str]) -> None:
        """One block of samples: ``values[k]`` is signal ``names[k]`` (kind "input"/"output") at ``t_s``."""
        with self._lock:
            self._check_open()
            t = np.asarray(t_s, dtype=np.float64)
            v = np.array(values, dtype=np.float64, copy=True)   # private copy: pyarrow wraps it
            names, kinds = list(names), list(kinds)
            if v.ndim == 1 and len(names) == 1:
                v = v[None, :]
            if t.ndim != 1:
                raise ValueError(f"t_s must be 1-D, got shape {t.shape}")
            if len(kinds) != len(names) or v.shape != (len(names), t.size):
                raise ValueError(f"values must have shape (len(names), len(t_s)) = ({len(names)}, {t.size}) with one "
                                 f"kind per name; got values {v.shape}, {len(names)} names, {len(kinds)} kinds")
            if t.size == 0:
                return
            if not np.all(np.isfinite(t)):
                bad = int(np.flatnonzero(~np.isfinite(t))[0])
                raise ValueError(f"t_s[{bad}] = {t[bad]!r} is not a finite flight time")
            times = rr.TimeColumn(TIMELINE, duration=_ns(t).astype("timedelta64[ns]"))
            for name, kind, row in zip(names, kinds, v):
                path = telemetry_path(kind, name)
                self._ensure_series(path, name)
                col = rr.ComponentColumn(self._d_scalars, _Arrow(pa.array(row)))
                self.rec.send_columns(path, indexes=[times], columns=[col])

    def log_estimate(self, t_s: float, omega: np.ndarray, outputs: Sequence[str], inputs: Sequence[str],
                     coherence: np.ndarray, magnitude_db: np.ndarray, phase_deg: np.ndarray,
                     adequacy_rows: Sequence[dict], verdict: str, reasons: Sequence[str]) -> None:
        """One spectral estimate at flight time ``t_s``; arrays are (n_out, n_in, n_f) over ``omega`` [rad/s]."""
        with self._lock:
            self._check_open()
            outputs, inputs = list(outputs), list(inputs)
            w = np.array(omega, dtype=np.float64, copy=True).ravel()
            if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0):
                raise ValueError("omega must be a non-empty 1-D array of finite frequencies > 0 rad/s")
            shape = (len(outputs), len(inputs), w.size)
            arrays = []
            for what, a in (("coherence", coherence), ("magnitude_db", magnitude_db), ("phase_deg", phase_deg)):
                a = np.array(a, dtype=np.float64, copy=True)
                if a.shape != shape:
                    raise ValueError(f"{what} must have shape (n_outputs, n_inputs, n_freq) = {shape}, got {a.shape}")
                arrays.append(a)
            coh, mag, pha = arrays
            self._set_time(t_s)
            g = self._grid_batches(w)
            logw = g["logw"]
            # (n_out, n_in, n_f, 2) float32 point arrays for all Bode strips at once; each pair's
            # strip wraps a contiguous view of these private arrays (no per-pair copies).
            mag_xy = np.empty(shape + (2,), np.float32)
            mag_xy[..., 0] = logw
            mag_xy[..., 1] = mag
            pha_xy = np.empty(shape + (2,), np.float32)
            pha_xy[..., 0] = logw
            pha_xy[..., 1] = pha
            mag_fin, pha_fin = np.isfinite(mag), np.isfinite(pha)
            mag_ok, pha_ok = mag_fin.all(axis=-1), pha_fin.all(axis=-1)
            mag_lo = np.min(mag, axis=-1, initial=np.inf, where=mag_fin)
            mag_hi = np.max(mag, axis=-1, initial=-np.inf, where=mag_fin)
            pha_lo = np.min(pha, axis=-1, initial=np.inf, where=pha_fin)
            pha_hi = np.max(pha, axis=-1, initial=-np.inf, where=pha_fin)
            wf_pct = None
            if self.waterfall_rows:
                wf_pct = np.clip(np.rint(np.nan_to_num(coh, nan=0.0) * 100.0), 0, 100).astype(np.uint8)
            n_f = w.size
            strip_offsets = _offsets(n_f)
            DCB = rr.DescribedComponentBatch
            rec = self.rec
            for io, o in enumerate(outputs):
                for ii, i in enumerate(inputs):
                    st = self._pair(o, i)
                    batches = [DCB(_Arrow(_tensor_array(coh[io, ii])), self._d_bar_values)]
                    if st.grid_key != g["key"]:   # abscissa/widths only when the grid changes (latest-at)
                        batches += g["bar"]
                        st.grid_key = g["key"]
                    rec.log(st.coh_path, batches)
                    for path, xy, ok, y in ((st.mag_path, mag_xy, mag_ok, mag), (st.phase_path, pha_xy, pha_ok, pha)):
                        if ok[io, ii]:
                            pts = pa.FixedSizeListArray.from_arrays(pa.array(xy[io, ii].ravel()),
                                                                    type=_STRIP_T.value_type)
                            strips = pa.ListArray.from_arrays(strip_offsets, pts, type=_STRIP_T)
                        else:
                            strips = _strips_array(_finite_runs(logw, y[io, ii]))
                        rec.log(path, [DCB(_Arrow(strips), self._d_strips)])
                    st.mag_extent = self._log_grid(st.mag_path, st.mag_extent, g, float(mag_lo[io, ii]),
                                                   float(mag_hi[io, ii]), "dB", (5.0, 10.0, 20.0))
                    st.phase_extent = self._log_grid(st.phase_path, st.phase_extent, g, float(pha_lo[io, ii]),
                                                     float(pha_hi[io, ii]), "deg", (15.0, 30.0, 45.0, 90.0))
                    if wf_pct is not None:
                        row = wf_pct[io, ii][None, :]
                        old = st.waterfall
                        if old is None or old.shape[1] != n_f:
                            new = row.copy()
                        else:
                            keep = old[len(old) - (self.waterfall_rows - 1):] if self.waterfall_rows > 1 else old[:0]
                            new = np.concatenate([keep, row])
                        st.waterfall = new   # a new array every time: the logged one is never mutated
                        st.wf_count += 1
                        if st.wf_count == 1 or st.wf_count % self.waterfall_every == 0:
                            rec.log(st.wf_path, [DCB(_Arrow(_tensor_array(new, g["dims"])), self._d_tensor)])
            if self._fraction_pairs:
                idx = {p: k for k, p in enumerate(self._fraction_pairs)}
                frac = np.full(len(self._fraction_pairs), np.nan)
                for r in adequacy_rows:
                    k = idx.get((r.get("output"), r.get("input")))
                    if k is not None and r.get("fraction") is not None:
                        frac[k] = float(r["fraction"])
                rec.log(FRACTION_PATH, rr.Scalars(frac))
            rec.log(ADEQUACY_PATH, rr.TextDocument(adequacy_markdown(t_s, adequacy_rows, verdict, reasons),
                                                   media_type=rr.MediaType.MARKDOWN))

    def log_alerts(self, t_s: float, alerts: Sequence[tuple[str, str]]) -> None:
        """Alerts as WARN text-log lines ``"[kind] message"`` at flight time ``t_s``."""
        with self._lock:
            self._check_open()
            alerts = list(alerts)
            if not alerts:
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


def _fmt_band(band) -> str:
    if band is None:
        return "—"
    if isinstance(band, str):
        return band or "—"
    b = list(band)
    if not b:
        return "—"
    if len(b) == 2 and all(isinstance(x, (int, float, np.floating, np.integer)) for x in b):
        return f"{float(b[0]):.3g} – {float(b[1]):.3g}"
    return ", ".join(_fmt_band(x) for x in b)


def _md(s) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ")


def adequacy_markdown(t_s: float, rows: Sequence[dict], verdict: str, reasons: Sequence[str]) -> str:
    """The adequacy table as markdown. A row's verdict is ``row["verdict"]`` when given, else
    "adequate" when it has an adequate band and "not adequate" when it has none."""
    lines = [f"**Verdict: {_md(verdict)}**  (flight time {float(t_s):.1f} s)", ""]
    lines += [f"- {_md(r)}" for r in reasons]
    if reasons:
        lines.append("")
    lines += ["| pair | adequate band [rad/s] | fraction | verdict |", "|---|---|---|---|"]
    for r in rows:
        band = r.get("band")
        frac = r.get("fraction")
        f = "—" if frac is None or not np.isfinite(float(frac)) else f"{100.0 * float(frac):.0f} %"
        has_band = _fmt_band(band) != "—"
        v = r.get("verdict") or ("adequate" if has_band else "not adequate")
        lines.append(f"| {_md(pair_label(r.get('output', '?'), r.get('input', '?')))} | {_md(_fmt_band(band))} | "
                     f"{f} | {_md(v)} |")
    return "\n".join(lines) + "\n"
