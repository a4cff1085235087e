"""What the CLI tells a new user: repairs as sentences (identify, replay, convert), and help that
names the plots' real format, every format convert reads and what `maps` is for."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

from livesweep import cli
from livesweep.convert import CONVERTERS
from livesweep.locks import LOCK_NAME

ROOT = Path(__file__).resolve().parents[1]
CHANNELS = (ROOT / "config" / "xv15_channels.toml").read_text()
SIGNALS = CHANNELS[CHANNELS.index("[signals.da]"):CHANNELS.index("[spectral]")]


def run(*argv) -> tuple[int, str, str]:
    """``livesweep ARGV`` in this process: exit status, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = cli.main([str(a) for a in argv])
        except SystemExit as e:                 # --help
            rc = e.code
    return rc, out.getvalue(), err.getvalue()


def _block(stdout: str, head: str) -> list[str]:
    """The lines under ``head`` (indented deeper than it)."""
    lines = stdout.splitlines()
    i = lines.index(head)
    depth = len(head) - len(head.lstrip()) + 1
    block = []
    for line in lines[i + 1:]:
        if len(line) - len(line.lstrip()) <= depth - 1:
            break
        block.append(line)
    return block


# ------------------------------------------------------------------------------------------------
# repairs: readable lines, never a Python dict
# ------------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_identify_prints_the_repairs_as_sentences_and_leaves_no_lock_file(tmp_path):
    from livesweep.sim.effects import make_effect
    from livesweep.sim.scenario import simulate, sweep_scenario
    from livesweep.telemetry.sim_telemetry import write_sim_log

    effects = (make_effect("spikes", output="r", rate_hz=0.1, magnitude=8.0),
               make_effect("dropouts", output="ay", count=2, duration_s=0.5))
    res = simulate(sweep_scenario("xv15-cruise", axes=("da",), repeats=2, amplitudes={"da": 3.0},
                                  off_axis_rms=0.2, effects=effects, seed=31))
    write_sim_log(res, tmp_path / "log.mcap")
    case = tmp_path / "case.toml"
    case.write_text(f'[case]\nname = "repairs"\naircraft = "XV-15"\n\n[[identify]]\nlog = "log.mcap"\n\n{SIGNALS}'
                    '[spectral]\ninputs = ["da"]\noutputs = ["p", "r", "ay"]\nband_rad_s = [0.3, 20.0]\n'
                    'sample_rate_hz = 50.0\n')
    out = tmp_path / "report"
    rc, stdout, stderr = run("identify", case, "--out", out, "--stage", "frequency-response", "--no-plots")
    assert rc == 0, stderr
    block = _block(stdout, "  repairs to the data:")
    assert block, stdout
    assert not any(c in line for line in block for c in "{}'"), block      # no dict, no quoted keys
    by_signal = dict(line.strip().split(": ", 1) for line in block)
    # the dropouts hit HIGHRES_IMU (p, r, ay); da is untouched and not named
    assert set(by_signal) == {"p", "r", "ay"}, block
    gaps = r"2 long gaps left out, not interpolated \(\d+ grid samples; no spectral window spans them\)"
    wild = r"\d+ wild points? replaced \(Hampel, window \d+ samples, \d+ sigma\)"
    assert re.fullmatch(gaps, by_signal["p"]), by_signal["p"]
    assert re.fullmatch(f"{gaps}; {wild}", by_signal["r"]), by_signal["r"]
    assert re.fullmatch(f"{gaps}(; {wild})?", by_signal["ay"]), by_signal["ay"]
    assert "nan_samples" not in stdout and "gaps_excluded" not in stdout
    # the report folder holds the report and no lock file: the lock went when identify finished
    assert (out / "report.json").is_file()
    assert not (out / LOCK_NAME).exists()


@pytest.mark.slow
def test_replay_prints_the_aligners_counts_as_words(tmp_path):
    log = tmp_path / "d.mcap"
    rc, _, stderr = run("sim", "--manoeuvre", "doublet", "--axis", "da", "--seed", "3",
                        "--effect", "dropouts:output=ay,count=2,duration_s=0.5", "--out", log)
    assert rc == 0, stderr
    r = subprocess.run([sys.executable, "-m", "livesweep", "replay", str(log)], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    stdout = r.stdout
    line = next(ln for ln in stdout.splitlines() if ln.startswith("  repairs and gaps: "))
    assert re.fullmatch(r"  repairs and gaps: \d+ grid samples left invalid in gaps \(not interpolated\)", line), line
    assert "samples_invalid" not in stdout and "{" not in line


def test_convert_prints_what_it_skipped_as_words(tmp_path):
    src = tmp_path / "t.csv"
    src.write_text("dt_mean 5\ntime,x\n0,1\n0.1,2\n0.2,3\n0.3,4\n0.4,5\n0.5,NaN\n")
    rc, stdout, stderr = run("convert", src, "--out", tmp_path / "t.mcap")
    assert rc == 0, stderr
    assert "  skipped: 1 preamble lines, 1 nonfinite cells; repaired: none" in stdout.splitlines()
    assert "{" not in stdout


def test_counts_text_leaves_out_zeros_and_says_none():
    assert cli._counts_text({"bad_crc": 0, "truncated_tail": 1}) == "1 truncated tail"
    assert cli._counts_text({"resets": 1, "late_dropped": 3}, cli._ALIGNER_WORDS) == \
        "1 clock reset, 3 late samples dropped"
    assert cli._counts_text({}) == "none"


# ------------------------------------------------------------------------------------------------
# help
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("verb", sorted(cli.EXAMPLES))
def test_no_help_calls_the_svg_plots_png(verb):
    rc, stdout, _ = run(verb, "--help")
    assert rc == 0
    assert "PNG" not in stdout
    if verb == "identify":
        assert "skip the SVG plots" in " ".join(stdout.split())


#: How convert's help names each format the converters read (a new converter must be named there).
CONVERT_FORMAT_WORDS = {"tlog": ".tlog", "dataflash": "DataFlash .bin", "ulog": ".ulg", "numpy": ".npy",
                        "text": "delimited text", "matlab": ".mat", "parquet": "Parquet"}


def test_convert_help_names_every_format_it_reads():
    assert set(CONVERT_FORMAT_WORDS) == set(CONVERTERS)
    rc, stdout, _ = run("convert", "--help")
    text = " ".join(stdout.split())
    for fmt, words in CONVERT_FORMAT_WORDS.items():
        assert words in text, fmt
    assert ".px4log" in text and "MCAP" in text
    rc, top, _ = run("--help")
    summary = " ".join(top.split())
    convert_line = summary[summary.index(" convert "):summary.index(" inspect ")]
    for words in (".tlog", ".bin", ".px4log", ".ulg", ".npy", ".mat", "Parquet", "text"):
        assert words in convert_line, words
    assert "--columns COLUMNS column map (TOML) for .npy, .mat, Parquet and text tables" in text


def test_maps_has_a_description():
    rc, stdout, _ = run("maps", "--help")
    assert rc == 0
    description = stdout.split("\n\n")[1]                  # usage, then the description, then options
    assert not description.startswith("options:")
    assert "channel-map presets" in description and "--map NAME" in " ".join(description.split())
    rc, top, _ = run("--help")
    assert re.search(r"\n    maps\s+list the channel-map presets", top)
