"""Fixtures shared by the test modules, and the ``slow`` marker.

``pytest -m "not slow"`` is the quick run for daily work; the README's command runs everything.
"""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Modules whose tests are mostly live pipelines, subprocesses, simulations or residual loops
#: (measured: each over ~10 s of the suite's time); the quick run leaves them out.
SLOW_MODULES = {
    "test_live_ardupilot.py", "test_residual_loop.py", "test_cli.py", "test_monitor.py", "test_online_estimator.py",
    "test_maps.py", "test_test_points.py", "test_stream_log.py", "test_monitor_hardening.py",
    "test_identify_residual_cli.py", "test_replay_logs.py", "test_identify_frequency_response.py",
    "test_library_face.py", "test_batch.py", "test_convert_damage.py", "test_foxglove.py", "test_convert_mavlink.py",
}


_CACHE_DIR = None


def pytest_configure(config):
    """The decoded-log cache of this run lives in a fresh folder, never the user's ~/.cache (the CLI
    subprocesses the tests start inherit it)."""
    global _CACHE_DIR
    import os
    import tempfile

    if "LIVESWEEP_CACHE_DIR" not in os.environ:
        _CACHE_DIR = tempfile.mkdtemp(prefix="livesweep-test-cache-")
        os.environ["LIVESWEEP_CACHE_DIR"] = _CACHE_DIR


def pytest_unconfigure(config):
    import shutil

    if _CACHE_DIR is not None:
        shutil.rmtree(_CACHE_DIR, ignore_errors=True)


def pytest_collection_modifyitems(config, items):
    slow = pytest.mark.slow
    for item in items:
        if item.path.name in SLOW_MODULES:
            item.add_marker(slow)


class _Said(list):
    def __call__(self, msg):
        self.append(msg)


@pytest.fixture(scope="session")
def cruise_run():
    """One :func:`livesweep.identify` of the shipped XV-15 cruise case (every stage), shared by the
    test modules, with the progress lines it gave."""
    import livesweep

    said = _Said()
    return livesweep.identify(ROOT / "config" / "xv15_cruise_lateral.toml", progress=said), list(said)


@pytest.fixture(scope="session")
def cruise_identification(cruise_run):
    return cruise_run[0]


@pytest.fixture(scope="session")
def cruise_report_dir(cruise_run, tmp_path_factory):
    """That identification written as ``livesweep identify`` writes it: ``(folder, report dict,
    console text)``, the console text being the progress lines and the summary."""
    import json

    import livesweep
    from livesweep.report.console import summary_lines

    ident, said = cruise_run
    out = tmp_path_factory.mktemp("cruise_report")
    path = livesweep.write_report(ident, out)
    text = "\n".join([f"[stage] {m}" for m in [*said, "writing the report"]] + summary_lines(ident)
                     + [f"wrote {path} and {out / 'report.html'}"])
    return out, json.loads(path.read_text()), text
