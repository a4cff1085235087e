"""Fixtures shared by the test modules.

``pytest -m "not slow"`` is the quick run for daily work; the README's command runs everything.
A test is marked ``slow`` (``@pytest.mark.slow`` on it, or ``pytestmark`` when every test of its
module is) by what it costs, never by the file it is in: the rule is the marker's description in
pyproject.toml. A module-scoped fixture counts toward the first test of the quick run that uses
it, so a fixture over the threshold makes all its users slow. The session fixtures below (one
identification of the XV-15 cruise case) are paid once by whichever test needs them first.
"""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

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


def _shared_data() -> Path:
    data = ROOT.parent / "shared" / "data"
    return data if data.is_dir() else Path("/work/shared/data")


#: The shared ArduCopter SITL SystemID DataFlash logs (a roll-rate and a pitch-rate chirp).
SITL_LOGS = {"roll": _shared_data() / "ardupilot_sitl_systemid" / "sid_axis7_rate_roll.bin",
             "pitch": _shared_data() / "ardupilot_sitl_systemid" / "sid_axis8_rate_pitch.bin"}


@pytest.fixture(scope="session")
def sitl_mcaps(tmp_path_factory):
    """The SITL SystemID logs converted once (``livesweep convert``): ``{"roll": mcap, "pitch": mcap}``;
    skips when the shared data is absent."""
    from livesweep.convert import convert

    missing = [str(p) for p in SITL_LOGS.values() if not p.is_file()]
    if missing:
        pytest.skip(f"shared ArduPilot SITL SystemID logs not found: {', '.join(missing)}")
    out = {}
    for axis, src in SITL_LOGS.items():
        out[axis] = tmp_path_factory.mktemp("sitl") / f"{axis}.mcap"
        convert(src, out[axis])
    return out


@pytest.fixture(scope="session")
def sitl_replays(sitl_mcaps, tmp_path_factory):
    """Each converted SITL log replayed through the monitor with the ``ardupilot-sysid-dataflash``
    preset and recorded: ``{axis: ReplayResult}`` (``.recording`` holds its /livesweep channels)."""
    import livesweep

    tmp = tmp_path_factory.mktemp("sitl_replay")
    return {axis: livesweep.replay(path, map="ardupilot-sysid-dataflash", record=tmp / f"{axis}.rec.mcap")
            for axis, path in sitl_mcaps.items()}
