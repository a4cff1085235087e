"""Reference computations for tests, written independently of livesweep's own code."""

from __future__ import annotations

import numpy as np


def phasors(t: np.ndarray, x: np.ndarray, omegas: np.ndarray) -> np.ndarray:
    """Complex amplitudes of ``x`` at ``omegas`` [rad/s] by linear least squares.

    Fits ``x = c0 + sum_k (a_k cos w_k t + b_k sin w_k t)`` and returns ``a_k - j b_k`` (the
    phasor convention of ``X e^{j w t}``).
    """
    t = np.asarray(t, float)
    cols = [np.ones_like(t)]
    for w in omegas:
        cols += [np.cos(w * t), np.sin(w * t)]
    A = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(A, np.asarray(x, float), rcond=None)
    a, b = coef[1::2], coef[2::2]
    return a - 1j * b


class Multisine:
    """Sum of equal-amplitude sines at integer multiples of ``2 pi / period_s`` with Schroeder phases."""

    def __init__(self, omegas, amplitude=1.0, period_s=20.0):
        self.omegas = np.asarray(omegas, float)
        self.amplitude = amplitude
        self.period_s = period_s
        n = len(self.omegas)
        self.phases = -np.pi * np.arange(n) * (np.arange(n) + 1) / n

    def __call__(self, t):
        t = np.asarray(t, float)
        return self.amplitude * sum(np.sin(w * t + ph) for w, ph in zip(self.omegas, self.phases))


def match_roots(actual, desired) -> tuple[np.ndarray, np.ndarray]:
    """Pair two sets of complex roots (eigenvalues, poles, zeros) by nearest neighbour.

    The pairing minimises the total distance ``sum |a_i - d_j|`` (``linear_sum_assignment``), so it
    does not depend on the order either set comes in. Sorted order is no pairing:
    ``np.sort_complex`` orders the two members of a conjugate pair by a last-bit difference in their
    real parts, which BLAS kernels and CPUs do not reproduce.

    Parameters
    ----------
    actual, desired : array_like of complex, same size
        Roots [rad/s].

    Returns
    -------
    actual, desired : ndarray of complex
        ``actual`` in its own order and ``desired`` reordered to match it.
    """
    from scipy.optimize import linear_sum_assignment

    a = np.asarray(actual, complex).ravel()
    d = np.asarray(desired, complex).ravel()
    assert a.size == d.size, f"{a.size} roots, expected {d.size}: {a} vs {d}"
    rows, cols = linear_sum_assignment(np.abs(a[:, None] - d[None, :]))
    return a[rows], d[cols]


def assert_roots_close(actual, desired, *, rtol: float = 1e-7, atol: float = 0.0):
    """``assert_allclose`` of two sets of roots paired by :func:`match_roots` (tolerances as numpy's)."""
    a, d = match_roots(actual, desired)
    np.testing.assert_allclose(a, d, rtol=rtol, atol=atol, err_msg="roots paired by nearest neighbour")


def db(x):
    return 20 * np.log10(np.abs(x))


def deg_wrap(x):
    """Angle in degrees wrapped to (-180, 180]."""
    return np.angle(np.exp(1j * np.deg2rad(x)), deg=True)


def collect_frames(src, n: int, timeout: float = 5.0, settle: float = 0.2) -> list:
    """Poll a frame source until ``n`` frames arrived (or ``timeout`` s), then ``settle`` s more for extras."""
    import time

    out: list = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += src.poll(0.05)
    end = time.monotonic() + settle
    while time.monotonic() < end:
        out += src.poll(0.02)
    return out


def tcp_listeners(port: int) -> list[str] | None:
    """Local addresses listening on TCP ``port`` per ``ss -ltn``; None when ``ss`` is not installed."""
    import shutil
    import subprocess

    ss = shutil.which("ss")
    if ss is None:
        return None
    out = subprocess.run([ss, "-ltnH"], capture_output=True, text=True, timeout=10).stdout
    found = []
    for line in out.splitlines():
        cols = line.split()
        if len(cols) >= 4:
            host, _, p = cols[3].rpartition(":")
            if p == str(port):
                found.append(host)
    return found


def simulated_record(result, rate_hz: float = 50.0, *, references: bool = False, names=None):
    """A simulated test point as one (n_signals, N) array at ``rate_hz`` (every signal is
    decimated from its own rate, which divides the simulator's): inputs, then (optionally) the
    injections as ``<input>_ref``, then outputs. Returns ``(values, names)``; NaNs kept."""
    sources = list(result.inputs.items())
    if references:
        sources += [(n + "_ref", s) for n, s in result.injections.items()]
    sources += list(result.outputs.items())
    if names is not None:
        sources = [(n, s) for n, s in sources if n in names]
    rows = [s.values[::int(round(s.rate_hz / rate_hz))] for _, s in sources]
    n = min(r.size for r in rows)
    return np.array([r[:n] for r in rows]), [name for name, _ in sources]


class CpuHog:
    """Processes that keep every core busy (a field laptop running a ground station and video): the
    live tests run beside them. A context manager; ``n`` defaults to the number of cores."""

    def __init__(self, n: int | None = None):
        import os

        self.n = n if n is not None else (os.cpu_count() or 2)
        self.procs: list = []

    def __enter__(self) -> "CpuHog":
        import subprocess
        import sys

        self.procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(self.n)]
        return self

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()


def copy_mcap_without(src, out, leave_out) -> int:
    """Copy an MCAP recording (schemas, channels, attachments, metadata) with the standard mcap
    reader and writer, leaving out each message for which ``leave_out(topic, data)`` is true;
    returns how many were left out."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    dropped = 0
    with open(src, "rb") as f, open(out, "wb") as g:
        r = make_reader(f)
        w = Writer(g)
        w.start(profile=r.get_header().profile, library="test")
        schemas, channels = {}, {}
        for schema, channel, msg in r.iter_messages(log_time_order=False):
            if channel.id not in channels:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(schema.id, 0) if schema else 0,
                                                          dict(channel.metadata))
            if leave_out(channel.topic, msg.data):
                dropped += 1
                continue
            w.add_message(channels[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        for a in r.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for m in r.iter_metadata():
            w.add_metadata(m.name, dict(m.metadata))
        w.finish()
    return dropped
