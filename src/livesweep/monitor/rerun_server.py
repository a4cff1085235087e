"""The bundled ``rerun`` CLI as a child process serving the web viewer on one address.

The Python serve functions of rerun-sdk bind 0.0.0.0; the monitor instead runs the CLI shipped
with rerun-sdk (``rerun --serve-web --bind HOST``), so the web viewer and its gRPC proxy listen on
the address the operator chose (``--rerun-bind``) only, and says in one line (:func:`serve_banner`)
where they are bound, warning when that is not a loopback address. The child gets SIGTERM when
this process dies (Linux) and is stopped with its whole session.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import weakref
from pathlib import Path

__all__ = ["find_rerun_cli", "serve_banner", "WebViewerServer"]


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


class WebViewerServer:
    """``rerun --serve-web --bind HOST --port GRPC --web-viewer-port WEB`` as a child process.

    Parameters
    ----------
    bind_host : str
        The one address both ports are bound to.
    grpc_port, web_port : int
        TCP ports of the gRPC proxy (where the monitor streams) and of the web viewer.
    start_timeout_s : float
        How long the child may take to bind both ports [s]; RuntimeError when it exits before,
        TimeoutError when it is not ready by then (its output in the message either way).

    Attributes
    ----------
    grpc_url : str
        Where to stream (``rerun+http://HOST:GRPC/proxy``).
    web_url : str
        The address to open in a browser on this machine.
    proc : subprocess.Popen
        The child.
    """

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
        """Everything the child printed so far (stdout and stderr)."""
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
        """Stop the child (SIGTERM to its session, SIGKILL after 5 s) and drop its output. Idempotent."""
        self._finalizer()  # idempotent: runs _stop_process at most once
        self._log.close()

