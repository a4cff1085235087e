"""The line the monitor prints when it serves the Rerun web viewer names the address the viewer is
really bound to (``--rerun-bind``), and warns in that same line when it is not a loopback address."""

from __future__ import annotations

import shutil
import socket

import pytest

from helpers import tcp_listeners
from livesweep.monitor.rerun_view import RerunView, find_rerun_cli, serve_banner

URL = "http://127.0.0.1:9090/?url=x"


@pytest.mark.parametrize("host, shown", [("127.0.0.1", "127.0.0.1"), ("127.0.0.2", "127.0.0.2"),
                                         ("::1", "[::1]"), ("localhost", "localhost")])
def test_a_loopback_address_is_named_without_a_warning(host, shown):
    line = serve_banner(host, 9090, 9876, URL)
    assert f"bound to {shown} ports 9090 (web) and 9876 (gRPC)" in line and URL in line
    assert "WARNING" not in line and "this machine only" in line and "\n" not in line


@pytest.mark.parametrize("host, shown, words", [
    ("0.0.0.0", "0.0.0.0", "every interface"),
    ("", "0.0.0.0", "every interface"),
    ("::", "[::]", "every interface"),
    ("192.168.1.5", "192.168.1.5", "not a loopback address"),
    ("host.invalid", "host.invalid", "not a loopback address"),     # unresolvable: warned, not trusted
])
def test_any_other_address_is_named_with_a_warning_in_the_same_line(host, shown, words):
    line = serve_banner(host, 9090, 9876, URL)
    assert f"bound to {shown} ports 9090 (web) and 9876 (gRPC)" in line
    assert f"WARNING: {words}" in line and "\n" not in line


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("bind, warned", [("0.0.0.0", True), ("127.0.0.1", False)])
def test_the_served_viewer_prints_the_address_it_is_bound_to(capfd, bind, warned):
    try:
        find_rerun_cli()
    except FileNotFoundError:
        pytest.skip("rerun CLI binary not available")
    grpc_port, web_port = _free_port(), _free_port()
    view = RerunView(["de"], ["q"], serve=True, bind_host=bind, grpc_port=grpc_port, web_port=web_port)
    try:
        listening = tcp_listeners(web_port) if shutil.which("ss") else None
    finally:
        view.close()
    lines = [ln for ln in capfd.readouterr().err.splitlines() if "Rerun web viewer" in ln]
    assert len(lines) == 1, lines
    assert f"bound to {bind} ports {web_port} (web) and {grpc_port} (gRPC)" in lines[0], lines[0]
    assert ("WARNING" in lines[0]) is warned, lines[0]
    if listening is not None:
        assert set(listening) == {bind}, listening
