"""Hostile case files: sizes beyond livesweep.limits, deep nesting, huge expressions and signal
names that are paths all give one-line ConfigErrors naming the file, key and value; the reference
case (1 kHz x 1 hour x 20 signals) stays inside every limit."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from livesweep import limits
from livesweep.config import load_case, load_channel_map
from livesweep.errors import ConfigError
from livesweep.ident.expression import compile_entry
from livesweep.ident.state_space import StateSpaceModel
from livesweep.report.writer import _plot_rel

CASE = """\
[case]
name = "t"

[[identify]]
log = "a.mcap"

[signals.u]
topic = "/x/u"
field = "val"

[signals.y]
topic = "/x/y"
field = "val"

[spectral]
inputs = ["u"]
outputs = ["y"]
band_rad_s = [0.5, 10.0]
sample_rate_hz = 50.0
"""


def _case(tmp_path: Path, text: str) -> Path:
    (tmp_path / "a.mcap").write_bytes(b"x")
    p = tmp_path / "case.toml"
    p.write_text(text)
    return p


def _error(tmp_path: Path, text: str) -> str:
    path = _case(tmp_path, text)
    with pytest.raises(ConfigError) as e:
        load_case(path)
    msg = str(e.value)
    assert str(path) in msg and "\n" not in msg and len(msg) < 600
    return msg


@pytest.mark.parametrize("replace, by, words", [
    ("sample_rate_hz = 50.0", "sample_rate_hz = 1e12", ["spectral.sample_rate_hz", "1000000000000.0", "100000"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nn_freq = 1000000000", ["spectral.n_freq", "1000000000", "10000"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nn_freq = 9223372036854775807",
     ["spectral.n_freq", "9223372036854775807"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindows_s = [10.0, 1e9]", ["spectral.windows_s[1]", "1000000000.0", "86400"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindows_s = [10.0, inf]", ["spectral.windows_s[1]", "inf"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\nwindows_s = [" + ", ".join(["5.0"] * 21) + "]",
     ["spectral.windows_s", "21 window lengths", "20"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = nan", ["spectral.sample_rate_hz", "nan"]),
    ("sample_rate_hz = 50.0", "sample_rate_hz = 50.0\noverlap = inf", ["spectral.overlap", "inf"]),
])
def test_spectral_sizes_beyond_the_limits_are_named(tmp_path, replace, by, words):
    msg = _error(tmp_path, CASE.replace(replace, by))
    for w in words:
        assert w in msg, (w, msg)


def _many_signals(n_in: int, n_out: int, n_freq: int) -> str:
    names = [f"s{k}" for k in range(n_in + n_out)]
    sigs = "".join(f'[signals.{n}]\ntopic = "/x"\nfield = "{n}"\n' for n in names)
    ins = ", ".join(f'"{n}"' for n in names[:n_in])
    outs = ", ".join(f'"{n}"' for n in names[n_in:])
    return (CASE.split("[signals.u]")[0] + sigs + f"[spectral]\ninputs = [{ins}]\noutputs = [{outs}]\n"
            f"band_rad_s = [0.5, 10.0]\nsample_rate_hz = 1000.0\nn_freq = {n_freq}\n")


def test_composite_size_is_bounded_over_outputs_inputs_frequencies_and_windows(tmp_path):
    # without windows_s the stage may choose up to MAX_WINDOWS (20) window lengths:
    # 50 outputs x 21 inputs x 10000 frequencies x 20 windows = 210e6 > 200e6
    msg = _error(tmp_path, _many_signals(21, 50, 10_000))
    assert "spectral.n_freq" in msg and "= 210000000 response values" in msg
    # 9000 frequencies: 189e6, inside the limit
    assert load_case(_case(tmp_path, _many_signals(21, 50, 9_000))).spectral.n_freq == 9_000


def test_reference_case_is_inside_every_limit(tmp_path):
    # 1 kHz x 1 hour x 20 signals, the reference the limits are sized around, with room to spare
    assert 1000 * 3600 * 20 * 2 <= limits.MAX_RECORD_VALUES
    assert 1000.0 <= limits.MAX_SAMPLE_RATE_HZ
    case = load_case(_case(tmp_path, _many_signals(5, 15, 500)))
    assert case.spectral.sample_rate_hz == 1000.0 and len(case.signals) == 20


def test_deeply_nested_toml_is_one_line_naming_the_file(tmp_path):
    p = tmp_path / "deep.toml"
    p.write_text("x = " + "[" * 10_000 + "]" * 10_000 + "\n")
    for loader in (load_case, load_channel_map):
        with pytest.raises(ConfigError, match="nested too deeply") as e:
            loader(p)
        assert str(p) in str(e.value)


def test_huge_config_file_is_refused_before_parsing(tmp_path):
    p = tmp_path / "big.toml"
    with open(p, "wb") as f:
        f.write(b"# " + b"x" * (limits.MAX_CONFIG_BYTES + 10) + b"\n")
    with pytest.raises(ConfigError, match="larger than") as e:
        load_case(p)
    assert str(p) in str(e.value)


def test_quoted_values_are_cut_to_a_line(tmp_path):
    long_list = "[" + ", ".join(["1.0"] * 100_000) + "]"
    msg = _error(tmp_path, CASE.replace("band_rad_s = [0.5, 10.0]", f"band_rad_s = {long_list}"))
    assert "spectral.band_rad_s" in msg and "..." in msg


@pytest.mark.parametrize("name", ["../../x", "a/b", "..", ".hidden", "a b", "x" * 65, "tab\tname", "a..b", "é"])
def test_signal_names_that_are_not_plain_names_are_refused(tmp_path, name):
    text = CASE.replace("[signals.y]", f'[signals."{name}"]').replace('outputs = ["y"]', f'outputs = ["{name}"]')
    msg = _error(tmp_path, text)
    assert "signal name" in msg


@pytest.mark.parametrize("name", ["p", "da_ref", "IMU.GyrX", "rate-roll", "p2", "_x"])
def test_plain_signal_names_load(tmp_path, name):
    text = CASE.replace("[signals.y]", f'[signals."{name}"]').replace('outputs = ["y"]', f'outputs = ["{name}"]')
    assert name in load_case(_case(tmp_path, text)).signals


def test_plot_names_stay_inside_plots_and_never_collide():
    taken: set[str] = set()
    rels = [_plot_rel(s, taken) for s in ("../../x_u", "a/b_c", "a_b_c", "a_b_c", "..", "verification_0")]
    assert rels == ["plots/_.._x_u.svg", "plots/a_b_c.svg", "plots/a_b_c_2.svg", "plots/a_b_c_3.svg", "plots/_.svg",
                    "plots/verification_0.svg"]
    assert _plot_rel("verification_0", taken) == "plots/verification_0_2.svg"
    for r in rels:
        assert Path(r).parent == Path("plots") and not Path(r).name.startswith(".")


# --- expressions -----------------------------------------------------------------------------

@pytest.mark.parametrize("text, words", [
    ("+".join(["a"] * 1000), ["F[0][0]", "more than 400"]),
    ("(" * 60 + "a" + ")" * 60, ["F[0][0]", "nested more than 50"]),
    ("-" * 60 + "a", ["F[0][0]", "nested more than 50"]),
    ("a" * 3000, ["F[0][0]", "3000 characters"]),
    ("1e400 * a", ["F[0][0]", "1e400", "float range"]),
    ("1e300 * 1e300 + a", ["F[0][0]", "overflows"]),
])
def test_expression_bounds_give_one_line_naming_the_entry(text, words):
    with pytest.raises(ConfigError) as e:
        compile_entry(text, {}, ["a"], "F[0][0]")
    msg = str(e.value)
    assert "\n" not in msg and len(msg) < 400
    for w in words:
        assert w in msg, (w, msg)


def test_expressions_inside_the_bounds_evaluate_exactly():
    e = compile_entry("+".join(["a"] * 199), {}, ["a"], "F[0][0]")          # 397 tokens
    assert e.value(np.array([2.0])) == 398.0
    e = compile_entry("(" * 49 + "-a*c" + ")" * 49, {"c": 3.0}, ["a"], "F[0][0]")
    assert e.value(np.array([2.0])) == -6.0


def test_state_space_dimension_is_bounded():
    n = limits.MAX_MODEL_DIMENSION + 1
    table = {"states": [f"x{k}" for k in range(n)], "inputs": ["u"], "outputs": ["y"]}
    with pytest.raises(ConfigError, match=f"states: {n} names; a model has at most"):
        StateSpaceModel.from_table(table, where="case.toml: state_space")


def test_window_spectra_values_counts_what_the_spectral_stage_allocates():
    from livesweep.spectral.spectra import window_spectra

    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, 5000))
    ws = window_spectra(x, ["a", "b", "c"], 50.0, 20.0, (0.5, 10.0), overlap=0.8)
    n_freq = ws.omega.size
    assert limits.window_spectra_values(3, 5000, 50.0, 20.0, 0.8, (0.5, 10.0)) == 3 * ws.n_segments * n_freq
    assert math.isclose(n_freq, (10.0 - 0.5) / (math.pi / 20.0) + 1, abs_tol=1)


@pytest.mark.parametrize("raw, words", [
    ({"band_rad_s": ["a", "b"]}, ["transfer_functions.p_da.band_rad_s", "'a'"]),
    ({"band_rad_s": [1.0, math.inf]}, ["transfer_functions.p_da.band_rad_s", "inf"]),
    ({"band_rad_s": [True, 2.0]}, ["transfer_functions.p_da.band_rad_s", "True"]),
    ({"delay": "no"}, ["transfer_functions.p_da.delay", "'no'", "true or false"]),
    ({"numerator": [1, 2]}, ["transfer_functions.p_da.numerator", "[1, 2]"]),
])
def test_transfer_function_table_numbers_and_flags_are_checked(tmp_path, raw, words):
    from livesweep.tf_tables import specs_of_tables

    table = {"output": "p", "input": "da", "denominator": "(1/T)", **raw}
    with pytest.raises(ConfigError) as e:
        specs_of_tables({"p_da": table}, tmp_path / "case.toml")
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_resampled_record_size_is_checked_before_resampling(tmp_path):
    """Ten samples 1e5 s apart resampled at 1 kHz would be 9e8 samples x 2 signals (14 GB)."""
    from livesweep.stages.frequency_response import run_frequency_response_stage
    from livesweep.telemetry.mcap_log import McapLogWriter

    with McapLogWriter(tmp_path / "a.mcap") as w:
        w.add_channel("/x", "X", {"type": "object"})
        for k in range(10):
            w.write("/x", {"t": k * 1e5, "u": float(k % 3), "y": float(k % 4)}, log_time_ns=k + 1)
    sigs = '[signals.u]\ntopic = "/x"\nfield = "u"\nstamp = "t"\n[signals.y]\ntopic = "/x"\nfield = "y"\nstamp = "t"\n'
    text = (CASE.split("[signals.u]")[0].replace('log = "a.mcap"', 'log = "a.mcap"\nlabel = "long"') + sigs
            + '[spectral]\ninputs = ["u"]\noutputs = ["y"]\nband_rad_s = [0.5, 10.0]\nsample_rate_hz = 1000.0\n')
    p = tmp_path / "case.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        run_frequency_response_stage(load_case(p))
    msg = str(e.value)
    for w in (str(p), "spectral.sample_rate_hz = 1000.0", "record 'long'", "0.0 to 900000.0 s",
              f"{(900_000 * 1000 + 1) * 2} samples x signals", str(limits.MAX_RECORD_VALUES)):
        assert w in msg, (w, msg)


@pytest.mark.parametrize("value", [math.inf, math.nan, 0.0, -1.0, 0.5, "x", True])
def test_residual_false_alarm_must_be_a_small_probability(tmp_path, value):
    from types import SimpleNamespace

    from livesweep.stages.residual import residual_settings

    case = SimpleNamespace(path=tmp_path / "case.toml", tables={"residual": {"false_alarm": value}})
    with pytest.raises(ConfigError, match=r"\[residual\]\.false_alarm = .*probability in \(0, 0.2\]"):
        residual_settings(case)


def test_residual_min_evidence_is_refused_with_what_replaced_it(tmp_path):
    from types import SimpleNamespace

    from livesweep.stages.residual import residual_settings

    case = SimpleNamespace(path=tmp_path / "case.toml", tables={"residual": {"min_evidence": {"time_delay": 50}}})
    with pytest.raises(ConfigError, match=r"min_evidence: no longer used.*set false_alarm"):
        residual_settings(case)


def test_segment_transforms_in_blocks_equal_one_transform_of_all_segments(monkeypatch):
    from numpy.lib.stride_tricks import sliding_window_view
    from scipy.signal import CZT

    import livesweep.spectral.transform as transform

    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, 20_000))
    n, fs = 1000, 100.0
    starts = np.arange(0, 19_000, 200)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / n)
    omega = transform.uniform_grid(0.5, 40.0, n / fs)
    seg = sliding_window_view(x, n, axis=-1)[:, starts, :]                # every segment at once
    seg = (seg - seg.mean(axis=-1, keepdims=True)) * w
    step = omega[1] - omega[0]
    ref = CZT(n, m=omega.size, w=np.exp(-1j * step / fs), a=np.exp(1j * omega[0] / fs))(seg, axis=-1)
    # The same numbers to rounding, not to the bit: a batch of transforms may take other SIMD/FMA
    # paths in the FFT than one transform does, which moves the last bits. Rounding in a chirp-z
    # transform of length 1000 (FFTs of 2048) is a few eps x log2(2048) of the largest value
    # (~1e-14 of it); a wrong block boundary or a lost segment is an error of order 1 of it.
    atol = 1e-12 * np.abs(ref).max()
    for block in (2**24, 7000, 3000):                                     # one block, 2 and 1 segments
        monkeypatch.setattr(transform, "_BLOCK_SAMPLES", block)
        np.testing.assert_allclose(transform.segment_transforms(x, starts, n, w, omega, fs), ref, rtol=0, atol=atol)


def test_analysis_refuses_spectra_beyond_the_limit_before_transforming(monkeypatch):
    import livesweep.spectral.analysis as analysis

    rng = np.random.default_rng(1)
    x = rng.standard_normal((2, 6000))
    size = max(limits.window_spectra_values(2, 6000, 50.0, w, 0.8, (1.0, 10.0)) for w in (10.0, 20.0))
    monkeypatch.setattr(analysis, "MAX_SPECTRAL_VALUES", size - 1)
    with pytest.raises(ConfigError, match=f"s window .* needs {size} spectral values, more than {size - 1}"):
        analysis.analyze(x, ["u", "y"], 50.0, ["u"], ["y"], (1.0, 10.0), windows_s=[10.0, 20.0])
    monkeypatch.setattr(analysis, "MAX_SPECTRAL_VALUES", size)
    assert analysis.analyze(x, ["u", "y"], 50.0, ["u"], ["y"], (1.0, 10.0), windows_s=[10.0, 20.0]).siso
