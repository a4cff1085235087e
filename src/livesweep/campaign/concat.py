"""Identification across flights: concatenate the test points of one axis into one case.

CIFER concatenates several runs of one axis into one frequency response: the spectral averages
of every run are pooled, so the random error falls (about as 1/sqrt(number of runs) for runs of
equal length and coherence; docs/method.md §2.1, §4.1). :func:`case_for_test_points` writes a
case file with one ``[[identify]]`` record per test point (a time slice of a log);
:func:`identify_test_points` writes it and runs :func:`livesweep.stages.identify.identify`.

How the frequency-response stage joins the records
(:func:`livesweep.stages.frequency_response.run_frequency_response_stage`): each record is read
and resampled onto the common grid on its own, the parts are joined end to end on one continuing
grid (:func:`livesweep.consistency.resample.concatenate`), and each part's mean (its trim) is
removed per signal before the spectra. The spectral windows are then slid over the joined record
as one series, so windows *do* span the joins (method §4.1, "windows may span record joins
provided each record starts and ends in trim"); only invalid (gap) samples are excluded. A test
point should therefore start and end in trim, with a few seconds of quiescent trim at each end.

Examples
--------
>>> from livesweep.campaign.concat import TestPointRef, identify_test_points   # doctest: +SKIP
>>> points = [TestPointRef("flight1.mcap", 105.0, 181.0, "roll sweep, flight 1"),
...           TestPointRef("flight2.mcap", 312.0, 388.0, "roll sweep, flight 2")]  # doctest: +SKIP
>>> ident = identify_test_points(points, map="config/xv15_channels.toml",
...                              inputs=["da"], outputs=["p"], band_rad_s=(0.7, 12.0))  # doctest: +SKIP
>>> ident.responses.pair("p", "da").random_error                                # doctest: +SKIP
"""

from __future__ import annotations

import os
import re
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

from livesweep.config import ChannelMap
from livesweep.errors import ConfigError
from livesweep.report.case_file import dumps_toml
from livesweep.settings import SignalSpec
from livesweep.stages.frequency_response import KINEMATIC_PAIRS

__all__ = ["TestPointRef", "case_for_test_points", "case_text_for_map", "identify_test_points"]


@dataclass(frozen=True)
class TestPointRef:
    """One test point: a time slice of a log.

    Attributes
    ----------
    log : pathlib.Path
        The MCAP file (written to the case as an absolute path).
    start_s, end_s : float
        Slice ``[start_s, end_s)`` on the signals' stamp clock [s]; ``start_s < end_s``. Include
        the trim before and after the sweep (a few seconds each): windows span the joins.
    label : str
        Words for reports; empty: the file name is shown.
    """

    __test__ = False                  # not a pytest class, whatever its name says

    log: Path
    start_s: float
    end_s: float
    label: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "log", Path(self.log))
        object.__setattr__(self, "start_s", float(self.start_s))
        object.__setattr__(self, "end_s", float(self.end_s))
        if not self.start_s < self.end_s:
            raise ConfigError(f"test point {self.label or self.log.name!r}: start_s = {self.start_s!r} must be "
                              f"before end_s = {self.end_s!r}")


def _signal_table(s: SignalSpec) -> dict:
    """The ``[signals.<name>]`` table of a SignalSpec (keys at their default left out)."""
    t: dict = {"topic": s.topic, "field": s.field}
    if s.stamp is not None:
        t["stamp"] = s.stamp
        t["stamp_scale"] = float(s.stamp_scale)
    if s.stamp_topic is not None:
        t["stamp_topic"] = s.stamp_topic
    if s.scale != 1.0:
        t["scale"] = float(s.scale)
    if s.offset != 0.0:
        t["offset"] = float(s.offset)
    if s.units:
        t["units"] = s.units
    if s.sysid is not None:
        t["sysid"] = int(s.sysid)
    if s.compid is not None:
        t["compid"] = int(s.compid)
    if s.where:
        t["where"] = {str(k): v for k, v in s.where}
    return t


def case_for_test_points(points: Sequence[TestPointRef], *, signals: dict[str, SignalSpec], inputs, outputs,
                         band_rad_s, sample_rate_hz: float, name: str, transfer_functions: dict | None = None,
                         criteria=None, windows_s=None, aircraft: str = "", condition: str = "") -> str:
    """Case-file TOML text identifying from ``points`` concatenated in order.

    Parameters
    ----------
    points : sequence of TestPointRef
        One ``[[identify]]`` record each, in order (at least one).
    signals : dict of str -> SignalSpec
        The ``[signals]`` tables to write (a channel map's ``signals``); every input and output
        must be among them.
    inputs, outputs : sequence of str
        ``[spectral]`` inputs and outputs (signal names).
    band_rad_s : (float, float)
        Band of the responses [rad/s].
    sample_rate_hz : float
        Uniform grid rate [Hz].
    name : str
        ``[case].name``.
    transfer_functions : dict, optional
        ``[transfer_functions.*]`` tables as written in a case file (name -> table).
    criteria : Criteria or dict, optional
        ``[criteria]``; None: the method's defaults.
    windows_s : sequence of float, optional
        Composite window lengths [s], each at most half the pooled record; None lets the spectral
        stage choose from the pooled record's length.
    aircraft, condition : str
        ``[case]`` words for reports.

    Returns
    -------
    str
        TOML text; :func:`livesweep.config.load_case` validates it once written to a file.

    Raises
    ------
    ConfigError
        No test points; an input or output not in ``signals``.
    """
    points = list(points)
    if not points:
        raise ConfigError("case_for_test_points: no test points given")
    inputs, outputs = [str(n) for n in inputs], [str(n) for n in outputs]
    missing = [n for n in (*inputs, *outputs) if n not in signals]
    if missing:
        raise ConfigError(f"case_for_test_points: {', '.join(missing)} not among the signals "
                          f"({', '.join(signals)})")
    head = {"name": str(name)}
    if aircraft:
        head["aircraft"] = aircraft
    if condition:
        head["condition"] = condition
    data: dict = {"case": head}
    records = []
    for p in points:
        rec = {"log": str(Path(p.log).resolve())}
        if p.label:
            rec["label"] = p.label
        rec["start_s"] = float(p.start_s)
        rec["end_s"] = float(p.end_s)
        records.append(rec)
    data["identify"] = records
    data["signals"] = {n: _signal_table(s) for n, s in signals.items()}
    spectral = {"inputs": inputs, "outputs": outputs, "band_rad_s": [float(b) for b in band_rad_s],
                "sample_rate_hz": float(sample_rate_hz)}
    if windows_s is not None:
        spectral["windows_s"] = [float(w) for w in windows_s]
    data["spectral"] = spectral
    if criteria is not None:
        data["criteria"] = dict(criteria) if isinstance(criteria, dict) else asdict(criteria)
    if transfer_functions:
        data["transfer_functions"] = {str(k): dict(v) for k, v in transfer_functions.items()}
    return dumps_toml(data)


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "case"


def identify_test_points(points: Sequence[TestPointRef], *, map, inputs=None, outputs=None, band_rad_s=None,
                         transfer_functions: dict | None = None, out_dir=None, name: str = "concatenated test points",
                         sample_rate_hz: float | None = None, windows_s=None, criteria=None):
    """Identify one frequency response from several test points of one axis, concatenated.

    Parameters
    ----------
    points : sequence of TestPointRef
        The test points, in order (different flights or times; same axis and condition).
    map : ChannelMap, str or os.PathLike
        The channel map (a preset name or a map file, :func:`livesweep.maps.load_map`).
    inputs, outputs : sequence of str, optional
        Default the map's ``[spectral]`` inputs / outputs.
    band_rad_s : (float, float), optional
        [rad/s]; default the map's band.
    transfer_functions : dict, optional
        ``[transfer_functions.*]`` tables; when given the transfer-function stage runs too.
    out_dir : str or os.PathLike, optional
        Folder the case file is written to (``<name>.toml``, created if needed) and kept in; None:
        a temporary folder, removed on return (``Identification.case.path`` then no longer exists).
    name : str
        ``[case].name``.
    sample_rate_hz : float, optional
        [Hz]; default the map's.
    windows_s : sequence of float, optional
        Composite window lengths [s]; None lets the spectral stage choose (the map's own
        ``windows_s`` are not used: they are sized for the map's usual record length).
    criteria : Criteria or dict, optional
        Default the map's ``[criteria]``.

    Returns
    -------
    livesweep.stages.identify.Identification
        Run up to the frequency-response stage, or the transfer-function stage with
        ``transfer_functions``.

    Raises
    ------
    ConfigError
        A map without ``[spectral]`` when inputs, outputs, band or rate are not all given; anything
        :func:`livesweep.config.load_case` or the stages refuse (naming the written case file).
    """
    from livesweep.stages.identify import identify

    text = case_text_for_map(points, map=map, inputs=inputs, outputs=outputs, band_rad_s=band_rad_s,
                             transfer_functions=transfer_functions, name=name, sample_rate_hz=sample_rate_hz,
                             windows_s=windows_s, criteria=criteria)
    until = "transfer-functions" if transfer_functions else "frequency-response"
    if out_dir is not None:
        folder = Path(out_dir)
        folder.mkdir(parents=True, exist_ok=True)
        case_path = folder / f"{_slug(name)}.toml"
        case_path.write_text(text)
        return identify(case_path, until=until)
    with tempfile.TemporaryDirectory(prefix="livesweep-concat-") as tmp:
        case_path = Path(tmp) / f"{_slug(name)}.toml"
        case_path.write_text(text)
        return identify(case_path, until=until)


def case_text_for_map(points: Sequence[TestPointRef], *, map, inputs=None, outputs=None, band_rad_s=None,
                      transfer_functions: dict | None = None, name: str = "concatenated test points",
                      sample_rate_hz: float | None = None, windows_s=None, criteria=None) -> str:
    """The case-file text :func:`identify_test_points` identifies (same parameters): the map's
    signals of the inputs and outputs (and their kinematic partners), its band, rate and criteria
    where not given."""
    from livesweep.maps import load_map

    cmap = map if isinstance(map, ChannelMap) else load_map(map if isinstance(map, os.PathLike) else str(map))
    sp = cmap.spectral
    need = {"inputs": inputs, "outputs": outputs, "band_rad_s": band_rad_s, "sample_rate_hz": sample_rate_hz}
    if sp is None and any(v is None for v in need.values()):
        raise ConfigError(f"{cmap.path}: the map has no [spectral] table; give "
                          + ", ".join(k for k, v in need.items() if v is None))
    inputs = list(sp.inputs if inputs is None else inputs)
    outputs = list(sp.outputs if outputs is None else outputs)
    used = [*inputs, *outputs]
    used += [a for a, r in KINEMATIC_PAIRS if r in used and a in cmap.signals and a not in used]
    signals = {n: cmap.signals[n] for n in cmap.signals if n in used}
    text = case_for_test_points(
        points, signals=signals, inputs=inputs, outputs=outputs,
        band_rad_s=sp.band_rad_s if band_rad_s is None else band_rad_s,
        sample_rate_hz=sp.sample_rate_hz if sample_rate_hz is None else sample_rate_hz, name=name,
        transfer_functions=transfer_functions, criteria=cmap.criteria if criteria is None else criteria,
        windows_s=windows_s)
    return text
