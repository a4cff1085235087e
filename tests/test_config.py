"""livesweep.config: the shipped case files load with the values written in them; every kind of
bad input raises ConfigError naming the file, the key path and the value."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from livesweep.config import Case, RecordSpec, SignalSpec, SpectralSettings, load_case, load_channel_map
from livesweep.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "config"
R2D = 57.29577951308232


# --------------------------------------------------------------------------------------------
# the shipped files
# --------------------------------------------------------------------------------------------


def test_cruise_case_loads_with_its_values():
    c = load_case(CONFIG / "xv15_cruise_lateral.toml")
    assert isinstance(c, Case)
    assert c.path == (CONFIG / "xv15_cruise_lateral.toml").resolve()
    assert (c.name, c.aircraft) == ("xv15-cruise-lateral", "XV-15")
    assert c.condition == "cruise, 170 kn TAS, airplane mode"
    logs = REPO / "replay_logs"
    assert c.identify == (
        RecordSpec((logs / "xv15_cruise_sweeps_da.mcap").resolve(), "aileron sweeps x2"),
        RecordSpec((logs / "xv15_cruise_sweeps_dr.mcap").resolve(), "rudder sweeps x2"),
    )
    assert [r.log.is_file() for r in c.identify + c.verify] == [True, True, True]
    assert c.verify[0].log.name == "xv15_cruise_verify.mcap"
    assert c.verify[0].label == "aileron doublet, rudder doublet, aileron 3-2-1-1"
    assert list(c.signals) == ["da", "dr", "p", "r", "ay", "beta", "phi"]
    assert c.signals["p"] == SignalSpec("p", "/mavlink/HIGHRES_IMU", "xgyro", "time_usec", 1e-6, R2D, 0.0, "deg/s")
    assert c.signals["p"].scale == 57.29577951308232
    assert c.signals["da"] == SignalSpec("da", "/mavlink/SERVO_OUTPUT_RAW", "servo1_raw", "time_usec", 1e-6,
                                         0.1, -150.0, "deg")
    assert c.signals["phi"].stamp == "time_boot_ms" and c.signals["phi"].stamp_scale == 1e-3
    assert c.signals["ay"].scale == 3.280839895013123
    assert c.spectral == SpectralSettings(("da", "dr"), ("p", "r", "ay", "beta"), (0.3, 20.0), 50.0,
                                          (7.0, 12.0, 20.0, 40.0, 80.0), 0.8, 150)
    assert sorted(c.tables) == ["state_space", "transfer_functions"]
    assert c.tables["state_space"]["constants"]["U0"] == 286.93
    assert c.tables["transfer_functions"]["p_da"]["numerator"] == "s [zeta_phi, w_phi]"


def test_hover_case_loads_with_its_values():
    c = load_case(CONFIG / "xv15_hover_lateral.toml")
    assert c.name == "xv15-hover-lateral"
    assert [r.log.name for r in c.identify] == ["xv15_hover_sweeps_da.mcap", "xv15_hover_sweeps_dr.mcap"]
    assert all(r.log.is_file() and r.start_s is None and r.end_s is None for r in c.identify)
    assert c.verify == ()
    assert c.spectral.band_rad_s == (0.2, 12.0)
    assert c.spectral.outputs == ("p", "r", "ay", "v", "phi")
    assert c.spectral.references == ("da_ref", "dr_ref")
    assert c.signals["da_ref"] == SignalSpec("da_ref", "/mavlink/DEBUG_VECT", "x", "time_usec", 1e-6, 1.0, 0.0, "deg")
    assert c.signals["v"] == SignalSpec("v", "/mavlink/ODOMETRY", "vy", "time_usec", 1e-6, 3.280839895013123, 0.0,
                                        "ft/s")
    assert list(c.tables) == ["state_space"]
    assert c.tables["state_space"]["parameters"]["Nda"] == {"value": 0.006}


def test_channel_map_loads():
    signals, spectral = load_channel_map(CONFIG / "xv15_channels.toml")
    assert list(signals) == ["da", "dr", "da_ref", "dr_ref", "p", "r", "ay", "beta", "v", "phi"]
    assert signals["dr"].field == "servo4_raw" and signals["dr"].offset == -150.0
    assert signals["beta"] == SignalSpec("beta", "/mavlink/AOA_SSA", "SSA", "time_usec", 1e-6, 1.0, 0.0, "deg")
    assert spectral.outputs == ("p", "r", "ay", "phi")
    assert spectral.windows_s == (7.0, 12.0, 20.0, 40.0, 80.0)


def test_channel_map_accepts_a_case_file_and_reads_only_its_signals_and_spectral():
    signals, spectral = load_channel_map(CONFIG / "xv15_cruise_lateral.toml")
    assert list(signals) == ["da", "dr", "p", "r", "ay", "beta", "phi"]
    assert spectral.outputs == ("p", "r", "ay", "beta")


# --------------------------------------------------------------------------------------------
# small files written here
# --------------------------------------------------------------------------------------------

BASE = """\
[case]
name = "t"
aircraft = "A"

[[identify]]
log = "a.mcap"
label = "first"
start_s = 10.0
end_s = 20.0

[[identify]]
log = "sub/b.mcap"

[signals.u]
topic = "/x/u"
field = "val"
stamp = "t_us"
stamp_scale = 1e-6
scale = 2.0
offset = -1.0
units = "deg"

[signals.y]
topic = "/x/y"
field = "val"

[spectral]
inputs = ["u"]
outputs = ["y"]
band_rad_s = [0.5, 10.0]
sample_rate_hz = 50.0
"""


@pytest.fixture()
def case_dir(tmp_path: Path) -> Path:
    (tmp_path / "a.mcap").write_bytes(b"x")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.mcap").write_bytes(b"x")
    return tmp_path


def _write(dir_: Path, text: str, name: str = "case.toml") -> Path:
    p = dir_ / name
    p.write_text(textwrap.dedent(text))
    return p


def test_small_case_loads_with_defaults_and_relative_logs(case_dir):
    c = load_case(_write(case_dir, BASE))
    assert c.identify[0] == RecordSpec((case_dir / "a.mcap").resolve(), "first", 10.0, 20.0)
    assert c.identify[1] == RecordSpec((case_dir / "sub" / "b.mcap").resolve(), "", None, None)
    assert c.condition == "" and c.verify == () and c.tables == {}
    assert c.signals["y"] == SignalSpec("y", "/x/y", "val")  # stamp None, stamp_scale 1, scale 1, offset 0
    assert c.signals["u"].scale == 2.0 and c.signals["u"].offset == -1.0
    assert c.spectral == SpectralSettings(("u",), ("y",), (0.5, 10.0), 50.0, None, 0.8, 150)


def test_case_with_only_frequency_response_tables_and_integers_as_floats(case_dir):
    text = BASE.replace("sample_rate_hz = 50.0", "sample_rate_hz = 100\nwindows_s = [5, 10.5]\noverlap = 0\nn_freq = 40")
    c = load_case(_write(case_dir, text))
    assert c.spectral.sample_rate_hz == 100.0 and isinstance(c.spectral.sample_rate_hz, float)
    assert c.spectral.windows_s == (5.0, 10.5) and c.spectral.overlap == 0.0 and c.spectral.n_freq == 40


def test_stage_tables_are_kept_for_their_stage(case_dir):
    text = BASE + '\n[residual]\nmax_steps = "x"\n'
    c = load_case(_write(case_dir, text))
    assert c.tables == {"residual": {"max_steps": "x"}}      # the residual stage validates it


@pytest.mark.parametrize("table", ["consistency", "verification"])
def test_tables_nothing_reads_are_refused(case_dir, table):
    with pytest.raises(ConfigError, match=rf"case\.toml: \[{table}\]: livesweep reads no \[{table}\] table .*remove it"):
        load_case(_write(case_dir, BASE + f"\n[{table}]\nwhatever = 3\n"))


BAD_CASES = [
    # (replace this, with this, strings the message must contain)
    ('aircraft = "A"', 'aircraft = "A"\ncolour = "red"', ["case.colour", "'colour'"]),
    ("[[identify]]\nlog = \"a.mcap\"", "[[identify]]\nlgo = \"x\"\nlog = \"a.mcap\"", ["identify[0].lgo", "'lgo'"]),
    ('units = "deg"', 'units = "deg"\nscal = 3.0', ["signals.u.scal", "'scal'"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindow = 3", ["spectral.window", "'window'"]),
    ("[case]", "[cases]\nx = 1\n[case]", ["cases", "unknown key"]),
    ("scale = 2.0", 'scale = "2.0"', ["signals.u.scale", "'2.0'", "number"]),
    ("scale = 2.0", "scale = true", ["signals.u.scale", "True"]),
    ("scale = 2.0", "scale = 0.0", ["signals.u.scale", "0.0"]),
    ("offset = -1.0", "offset = nan", ["signals.u.offset", "nan", "finite"]),
    ("stamp_scale = 1e-6", "stamp_scale = -1e-6", ["signals.u.stamp_scale", "-1e-06"]),
    ('topic = "/x/u"\n', "", ["signals.u", "'topic'"]),
    ('[signals.y]\ntopic = "/x/y"\nfield = "val"', '[signals.y]\ntopic = "/x/y"', ["signals.y", "'field'"]),
    ('[signals.y]\ntopic = "/x/y"', '[signals.y]\ntopic = 5', ["signals.y.topic", "5"]),
    ('[signals.y]\ntopic = "/x/y"\nfield = "val"', '[signals.y]\ntopic = "/x/y"\nfield = "val"\nstamp_scale = 0.001',
     ["signals.y.stamp_scale", "0.001", "without 'stamp'"]),
    ("start_s = 10.0", "start_s = 20.0", ["identify[0].start_s", "20.0", "end_s"]),
    ("start_s = 10.0", "start_s = 25.0", ["identify[0].start_s", "25.0"]),
    ("end_s = 20.0", "end_s = inf", ["identify[0].end_s", "inf"]),
    ('label = "first"', "label = 3", ["identify[0].label", "3"]),
    ('log = "sub/b.mcap"', 'log = "sub/c.mcap"', ["identify[1].log", "sub/c.mcap"]),
    ('log = "sub/b.mcap"', 'log = "sub"', ["identify[1].log", "directory"]),
    ('[[identify]]\nlog = "sub/b.mcap"', '[[identify]]\nlog = "sub/b.mcap"\nstart_s = "10"',
     ["identify[1].start_s", "'10'"]),
    ('outputs = ["y"]', 'outputs = ["y", "q"]', ["spectral.outputs[1]", "'q'", "u, y"]),
    ('inputs = ["u"]', 'inputs = ["w"]', ["spectral.inputs[0]", "'w'"]),
    ('inputs = ["u"]', 'inputs = ["u"]\nreferences = ["u", "y"]', ["spectral.references", "one reference per input"]),
    ('inputs = ["u"]', 'inputs = ["u"]\nreferences = ["r9"]', ["spectral.references[0]", "'r9'"]),
    ('inputs = ["u"]', 'inputs = ["u"]\nreferences = ["y"]', ["spectral.references[0]", "exogenous", "'y'"]),
    ('outputs = ["y"]', 'outputs = ["y", "u"]', ["spectral.inputs[0]", "'u'", "outputs"]),
    ('outputs = ["y"]', 'outputs = ["y", "y"]', ["spectral.outputs[1]", "twice"]),
    ('outputs = ["y"]', "outputs = []", ["spectral.outputs", "[]"]),
    ('outputs = ["y"]', 'outputs = "y"', ["spectral.outputs", "'y'", "array"]),
    ('outputs = ["y"]\n', "", ["spectral", "'outputs'"]),
    ("band_rad_s = [0.5, 10.0]\n", "", ["spectral", "'band_rad_s'"]),
    ("sample_rate_hz = 50.0\n", "", ["spectral", "'sample_rate_hz'"]),
    ('inputs = ["u"]\n', "", ["spectral", "'inputs'"]),
    ("band_rad_s = [0.5, 10.0]", "band_rad_s = [0.0, 10.0]", ["spectral.band_rad_s", "[0.0, 10.0]", "> 0"]),
    ("band_rad_s = [0.5, 10.0]", "band_rad_s = [-1.0, 10.0]", ["spectral.band_rad_s", "[-1.0, 10.0]"]),
    ("band_rad_s = [0.5, 10.0]", "band_rad_s = [10.0, 10.0]", ["spectral.band_rad_s", "[10.0, 10.0]", "below"]),
    ("band_rad_s = [0.5, 10.0]", "band_rad_s = [12.0, 10.0]", ["spectral.band_rad_s", "[12.0, 10.0]"]),
    ("band_rad_s = [0.5, 10.0]", "band_rad_s = [0.5]", ["spectral.band_rad_s", "[0.5]"]),
    ("band_rad_s = [0.5, 10.0]", "band_rad_s = [0.5, 200.0]", ["spectral.band_rad_s", "Nyquist", "157.08"]),
    ("band_rad_s = [0.5, 10.0]", 'band_rad_s = [0.5, "x"]', ["spectral.band_rad_s[1]", "'x'"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 0.0", ["spectral.sample_rate_hz", "0.0"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = -50.0", ["spectral.sample_rate_hz", "-50.0"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = nan", ["spectral.sample_rate_hz", "nan"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\noverlap = 0.96", ["spectral.overlap", "0.96", "[0, 0.95]"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\noverlap = -0.1", ["spectral.overlap", "-0.1"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindows_s = [10.0, 0.0]", ["spectral.windows_s[1]", "0.0"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindows_s = [10.0, -3]", ["spectral.windows_s[1]", "-3"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindows_s = []", ["spectral.windows_s", "[]"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nn_freq = 1.5", ["spectral.n_freq", "1.5"]),
    ('name = "t"\n', "", ["case", "'name'"]),
    ('[case]\nname = "t"\naircraft = "A"\n', "", ["case", "missing"]),
    ('name = "t"', "name = 1", ["case.name", "1"]),
]


@pytest.mark.parametrize("old,new,needles", BAD_CASES, ids=[n[0] for _, _, n in BAD_CASES])
def test_bad_case_raises_config_error_naming_file_key_and_value(case_dir, old, new, needles):
    assert old in BASE, old
    path = _write(case_dir, BASE.replace(old, new, 1))
    with pytest.raises(ConfigError) as err:
        load_case(path)
    msg = str(err.value)
    assert str(path.resolve()) in msg
    for needle in needles:
        assert needle in msg, (needle, msg)


def test_missing_log_names_the_resolved_path(case_dir):
    path = _write(case_dir, BASE.replace('log = "a.mcap"', 'log = "../elsewhere/missing.mcap"'))
    with pytest.raises(ConfigError, match="does not exist") as err:
        load_case(path)
    assert str((case_dir.parent / "elsewhere" / "missing.mcap").resolve()) in str(err.value)
    assert "identify[0].log" in str(err.value)


def test_no_identify_records_is_an_error(case_dir):
    text = BASE.split("[[identify]]")[0] + "[signals" + BASE.split("[signals", 1)[1]
    with pytest.raises(ConfigError, match=r"identify.*at least one"):
        load_case(_write(case_dir, text))


def test_verify_records_are_validated_like_identify(case_dir):
    text = BASE + '\n[[verify]]\nlog = "a.mcap"\nstart_s = 5.0\nend_s = 1.0\n'
    with pytest.raises(ConfigError, match=r"verify\[0\]\.start_s.*5\.0"):
        load_case(_write(case_dir, text))
    text = BASE + '\n[[verify]]\nlog = "a.mcap"\nlabel = "doublet"\nstart_s = 5.0\n'
    c = load_case(_write(case_dir, text))
    assert c.verify == (RecordSpec((case_dir / "a.mcap").resolve(), "doublet", 5.0, None),)


def test_toml_syntax_error_names_file_and_line(case_dir):
    path = _write(case_dir, BASE.replace("scale = 2.0", "scale = = 2.0"))
    line = BASE.splitlines().index("scale = 2.0") + 1
    with pytest.raises(ConfigError) as err:
        load_case(path)
    msg = str(err.value)
    assert str(path) in msg and "TOML syntax error" in msg and f"line {line}" in msg


def test_missing_and_non_utf8_files(tmp_path):
    with pytest.raises(ConfigError, match="does not exist") as err:
        load_case(tmp_path / "nope.toml")
    assert "nope.toml" in str(err.value)
    p = tmp_path / "latin1.toml"
    p.write_bytes(b'[case]\nname = "caf\xe9"\n')
    with pytest.raises(ConfigError, match="UTF-8"):
        load_case(p)


def test_identify_must_be_an_array_of_tables(case_dir):
    text = BASE.replace('[[identify]]\nlog = "sub/b.mcap"\n', "").replace(
        '[[identify]]\nlog = "a.mcap"\nlabel = "first"\nstart_s = 10.0\nend_s = 20.0\n', "")
    text = 'identify = "a.mcap"\n' + text
    with pytest.raises(ConfigError, match=r"identify: must be an array of tables.*'a\.mcap'"):
        load_case(_write(case_dir, text))


def test_channel_map_errors(tmp_path):
    good = BASE.split("[signals.u]", 1)[1]
    good = "[signals.u]" + good
    signals, spectral = load_channel_map(_write(tmp_path, good, "map.toml"))
    assert list(signals) == ["u", "y"] and spectral.inputs == ("u",)
    signals, spectral = load_channel_map(_write(tmp_path, good.split("[spectral]")[0], "map.toml"))
    assert spectral is None
    with pytest.raises(ConfigError, match=r"map\.toml: extra: unknown key 'extra'"):
        load_channel_map(_write(tmp_path, "extra = 1\n" + good, "map.toml"))
    with pytest.raises(ConfigError, match=r"map\.toml: signals: missing"):
        load_channel_map(_write(tmp_path, "[spectral]\n", "map.toml"))
    with pytest.raises(ConfigError, match=r"signals\.u\.units.*3"):
        load_channel_map(_write(tmp_path, good.replace('units = "deg"', "units = 3"), "map.toml"))
    with pytest.raises(ConfigError, match=r"signals: must define at least one signal"):
        load_channel_map(_write(tmp_path, "[signals]\n", "map.toml"))


@pytest.mark.parametrize("band, message", [
    ([0.0, 1.0], r"b = \[0.0, 1.0\]: the lower end must be > 0 rad/s"),
    ([2.0, 1.0], r"the lower end must be below the upper end"),
    ([1.0, float("nan")], r"b\[1\] = nan: must be a finite number"),
    ("0.5, 2", r"must be \[low, high\], two numbers"),
    ([1.0, 160.0], r"Nyquist frequency pi \* sample_rate_hz = 157.08 rad/s \(50 Hz\)"),
])
def test_one_band_check_for_every_band(band, message):
    from livesweep.errors import check_band

    with pytest.raises(ConfigError, match=message):
        check_band(band, "b", sample_rate_hz=50.0)
    assert check_band((0.5, 20), "b", sample_rate_hz=50.0) == (0.5, 20.0)
