"""The settings tree: what a case file and a channel map say, as frozen, typed dataclasses.

Each key of a TOML table is one field here, declared once with its type, units, default, range
and meaning (:func:`livesweep.settings_schema.setting`); :mod:`livesweep.config` reads the files
into these objects, and docs/case-file.md's reference tables are generated from them
(``python -m livesweep.settings``). Stages, the monitor and the report receive these
objects; the adequacy and GO criteria are :class:`~livesweep.spectral.criteria.Criteria`
(``[criteria]``).

Units: times in seconds on the signals' stamp clock (vehicle time), frequencies in rad/s, sample
rates in Hz.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from livesweep import limits
from livesweep.ident.envelope import NO_MODEL_SETTINGS, EnvelopeLimits, ModelSettings, Prediction
from livesweep.settings_schema import Check, choices, integer, names, number, numbers, setting, string, write_docs
from livesweep.spectral.criteria import DEFAULT_CRITERIA, Criteria

__all__ = ["SignalSpec", "RecordSpec", "SpectralSettings", "TestPointSettings", "ChannelMap", "Case", "Criteria",
           "TEST_POINT_SOURCES", "DOCUMENTED_TABLES", "regenerate_docs"]

#: Where test points may come from (:mod:`livesweep.monitor.testpoints`).
TEST_POINT_SOURCES = ("autopilot", "marker", "sweep")


@dataclass(frozen=True)
class SignalSpec:
    """Where a named signal lives in a log and how to turn the raw field into engineering units.

    Attributes
    ----------
    name : str
        The signal's name in the case (``"p"``, ``"da"``).
    topic : str
        MCAP channel topic, e.g. ``"/mavlink/HIGHRES_IMU"``.
    field : str
        Field of the JSON message (exact key or dotted path, ``"gyro.x"``, ``"servo.0"``), or an
        arithmetic expression of such fields (``"servo2_raw - servo1_raw"``,
        :func:`livesweep.telemetry.extract.parse_field`).
    stamp : str or None
        Field holding the vehicle time of the sample; None to use the MCAP ``log_time``
        (receive time, ns).
    stamp_topic : str or None
        The topic whose ``stamp`` field times this signal, when its own messages carry no time
        (MAVLink PID_TUNING): each message takes the stamp of the latest message of that topic
        received before it (ArduCopter sends both in one telemetry tick), so the signal is on the
        vehicle clock at any replay speed. None: ``stamp`` is a field of the signal's own topic.
    stamp_scale : float
        Seconds per stamp unit (``1e-6`` for ``time_usec``). 1.0 when ``stamp`` is None.
    scale, offset : float
        ``value = scale * raw + offset`` in ``units`` (``raw``: the field, or the expression's value).
    units : str
        Units of the scaled value (free text, e.g. ``"deg/s"``).
    sysid, compid : int or None
        Take only messages of this MAVLink system / component (their ``sysid`` / ``compid``
        fields); None: any (the live aligner then follows the first vehicle it sees).
    where : tuple of (str, number)
        Take only messages whose field equals the value, every pair at once (``(("axis", 1),)``
        for the roll axis of MAVLink PID_TUNING, ``(("I", 0),)`` for a DataFlash instance). A
        mapping or a list of pairs is accepted and stored as a tuple of pairs.
    """

    name: str
    topic: str
    field: str
    stamp: str | None = None
    stamp_scale: float = 1.0
    scale: float = 1.0
    offset: float = 0.0
    units: str = ""
    sysid: int | None = None
    compid: int | None = None
    where: tuple = ()
    stamp_topic: str | None = None

    def __post_init__(self) -> None:
        w = self.where
        pairs = tuple(w.items()) if isinstance(w, Mapping) else tuple(tuple(p) for p in (w or ()))
        if any(len(p) != 2 for p in pairs):
            raise TypeError(f"signal {self.name!r}: where must be field -> value pairs, got {w!r}")
        object.__setattr__(self, "where", pairs)


@dataclass(frozen=True)
class RecordSpec:
    """One log (or a time slice of it) to read.

    Attributes
    ----------
    log : pathlib.Path
        The MCAP file, resolved relative to the case file.
    label : str
        Words for reports (``"aileron sweeps x2"``).
    start_s, end_s : float or None
        Slice ``[start_s, end_s)`` on the signals' stamp clock [s]; None for the start or end of
        the log.
    """

    log: Path = setting(check=Check(None, "string"), units="—",
                        doc="the MCAP file, relative to the case file; it must exist")
    label: str = setting("", string(), "words for the report", default_text='`""` (the file name is shown)')
    start_s: float | None = setting(None, number(), "first time used, inclusive", units="s (stamp clock)",
                                    default_text="start of the log")
    end_s: float | None = setting(None, number(), "end of the slice, exclusive; `start_s < end_s`",
                                  units="s (stamp clock)", default_text="end of the log")


@dataclass(frozen=True)
class SpectralSettings:
    """Spectral settings of a case or channel map.

    Attributes
    ----------
    inputs, outputs : tuple of str
        Signal names (disjoint; every name is in ``[signals]``).
    band_rad_s : (float, float)
        Frequency band of interest [rad/s], ``0 < lo < hi < pi * sample_rate_hz``.
    sample_rate_hz : float
        Uniform resampling rate [Hz].
    windows_s : tuple of float or None
        Window lengths for the composite [s]; None lets the spectral stage choose.
    overlap : float
        Window overlap fraction in ``[0, 0.95]``.
    n_freq : int
        Number of frequency points over the band.
    references : tuple of str or None
        One exogenous reference per input (e.g. the logged sweep injection of a closed-loop test
        point), in ``inputs`` order; the responses are then formed as (y/r)(u/r)^-1, free of the
        bias of disturbances fed back into the inputs (docs/method.md §4.6). None: plain MISO.
    """

    inputs: tuple[str, ...] = setting(check=Check(None, "array of signal names"),
                                      doc="the controls (at least one; no repeats)")
    outputs: tuple[str, ...] = setting(check=Check(None, "array of signal names"),
                                       doc="the responses (at least one; none is also an input)")
    band_rad_s: tuple[float, float] = setting(check=Check(None, "`[low, high]`"), units="rad/s",
                                              doc="band of the responses: `0 < low < high < π·sample_rate_hz`")
    sample_rate_hz: float = setting(check=number(0.0, limits.MAX_SAMPLE_RATE_HZ, lo_open=True), units="Hz",
                                    doc="the uniform grid every signal is resampled onto")
    windows_s: tuple[float, ...] | None = setting(
        None, numbers(number(0.0, limits.MAX_WINDOW_S, lo_open=True), max_items=limits.MAX_WINDOWS,
                                                                       what="window lengths"), units="s",
        default_text="chosen (method §4.4)", doc="composite window lengths; each at most half the record")
    overlap: float = setting(0.8, number(0.0, 0.95), "window overlap", units="fraction")
    n_freq: int = setting(150, integer(2, limits.MAX_N_FREQ), "points of the log-spaced composite grid over "
                          "`band_rad_s`")
    references: tuple[str, ...] | None = setting(
        None, Check(None, "array of signal names"),
        "one exogenous reference per input, in `inputs` order (the logged sweep injections of a closed-loop "
        "test point); responses are then formed as (y/r)(u/r)⁻¹ (method §4.6)")


@dataclass(frozen=True)
class TestPointSettings:
    """A channel map's ``[test_points]`` table: where test points come from and what each must cover.

    Attributes
    ----------
    sources : tuple of str
        Evidence that opens and closes a test point, any of ``"autopilot"`` (ArduPilot SystemID),
        ``"marker"`` (the operator) and ``"sweep"`` (detected oscillation); default all three.
    axes : dict of int -> str
        ArduPilot ``SID_AXIS`` number -> the input that axis sweeps (1/2/3 input roll/pitch/yaw,
        4/5/6 recovery, 7/8/9 rate, 10/11/12 mixer, 13 mixer thrust); empty by default.
    required : dict of str -> tuple of str
        For every input of ``[spectral]``: the outputs whose pairs must be adequate when it is
        swept. An input the table does not name gets the output at its own list position (or
        every output when there are fewer outputs than that).
    min_duration_s : float
        A detected sweep shorter than this is no test point [s]; default 10.
    conditions : tuple of str
        Signals of ``[signals]`` averaged over each test point (the conditions its model's trend
        is read against); none by default.
    """

    __test__ = False                  # not a pytest class, whatever its name says

    sources: tuple[str, ...] = setting(TEST_POINT_SOURCES, choices(TEST_POINT_SOURCES),
                                       "evidence that opens and closes a test point", default_text="all three")
    axes: dict = setting(factory=dict, check=Check(None, 'table `"N"` = input name'), default_text="empty",
                         doc="ArduPilot `SID_AXIS` number (1–255) → the input that axis sweeps (1/2/3 input "
                             "roll/pitch/yaw, 4/5/6 recovery, 7/8/9 rate, 10/11/12 mixer, 13 mixer thrust). List "
                             "only the axes whose injection the map's input carries: a test point the autopilot "
                             "opens on an axis not listed is NO-GO, \"not judged with this map\" (the rate-loop "
                             "presets leave out the mixer axes, whose chirp enters after the rate loop)")
    required: dict = setting(factory=dict, check=Check(None, "table input = array of outputs"),
                             default_text="each input's on-axis output",
                             doc="the pairs that must be adequate when that input is swept; an input not named gets "
                                 "the output at its own list position (all outputs when there are fewer outputs "
                                 "than that)")
    min_duration_s: float = setting(10.0, number(0.0), "a detected sweep shorter than this is no test point "
                                    "(a doublet)", units="s")
    conditions: tuple = setting((), names(), "signals of `[signals]` averaged over each test point, to read its "
                                "model's trend against (airspeed, altitude); not analysed", default_text="none")


@dataclass(frozen=True)
class ChannelMap:
    """A validated channel map (a named preset or a file).

    Attributes
    ----------
    name : str
        ``[map].name`` (a preset's name); the file name without ``.toml`` when absent.
    description, needs : str
        ``[map].description`` and ``[map].needs`` (what telemetry, rates and parameters it needs);
        empty when absent.
    path : pathlib.Path
        The file (resolved).
    signals : dict[str, SignalSpec]
        ``[signals]``, in file order.
    spectral : SpectralSettings or None
        ``[spectral]``; None when absent.
    test_points : TestPointSettings or None
        ``[test_points]`` with its defaults filled in; None when the table is absent.
    vehicle : dict of str -> tuple of float
        ``[map.vehicle]``: the vehicle this map is made for, as parameter values
        (``FRAME_CLASS``, ``FRAME_TYPE``) and ``MAV_TYPE`` (its HEARTBEAT type), each one or more
        allowed values; the monitor and ``inspect`` check them against what the vehicle says.
    system : (int, int or None) or None
        ``[map].sysid`` and ``[map].compid``: the MAVLink system (and component) the monitor
        analyses; None: the first vehicle that sends every mapped signal
        (:class:`~livesweep.telemetry.align.GridAligner`).
    criteria : Criteria
        ``[criteria]``: what makes a response adequate and a test point GO (default the method's).
    models : ModelSettings
        ``[transfer_functions.*]``, ``[predictions.*]`` and ``[limits]``: what each test point's
        model is fitted with and held to (:mod:`livesweep.ident.test_point_model`).
    """

    name: str
    description: str
    needs: str
    path: Path
    signals: dict[str, SignalSpec]
    spectral: SpectralSettings | None
    test_points: TestPointSettings | None
    vehicle: dict = field(default_factory=dict)
    system: tuple | None = None
    criteria: Criteria = DEFAULT_CRITERIA
    models: ModelSettings = NO_MODEL_SETTINGS


@dataclass(frozen=True)
class Case:
    """A validated case file.

    Attributes
    ----------
    path : pathlib.Path
        The case file (resolved).
    name, aircraft, condition : str
        From ``[case]``.
    identify, verify : tuple of RecordSpec
        Records to identify from (concatenated in order) and to verify against.
    signals : dict[str, SignalSpec]
        From ``[signals]``, in file order.
    spectral : SpectralSettings or None
        From ``[spectral]``; None when the table is absent.
    criteria : Criteria
        From ``[criteria]``: what makes a response adequate and a test point GO (default the method's).
    tables : dict
        The raw TOML tables of later stages (any of ``transfer_functions``, ``state_space``,
        ``residual`` that are present), unparsed here; ``identify`` parses them once into typed
        specs (:func:`livesweep.stages.identify.parse_case_specs`).
    """

    path: Path = setting(key=False)
    name: str = setting(check=string(nonempty=True), doc="the case's name: report titles, the batch folder name")
    aircraft: str = setting("", string(), "the airframe")
    condition: str = setting("", string(), "the flight condition of the test point")
    identify: tuple[RecordSpec, ...] = setting((), key=False)
    verify: tuple[RecordSpec, ...] = setting((), key=False)
    signals: dict[str, SignalSpec] = setting(factory=dict, key=False)
    spectral: SpectralSettings | None = setting(None, key=False)
    tables: dict = setting(factory=dict, key=False)
    criteria: Criteria = setting(DEFAULT_CRITERIA, key=False)


#: The tables docs/case-file.md documents from their fields, by the name its markers use
#: (``<!-- settings: spectral -->``).
DOCUMENTED_TABLES = {"case": Case, "record": RecordSpec, "spectral": SpectralSettings, "criteria": Criteria,
                     "test_points": TestPointSettings, "limits": EnvelopeLimits, "predictions": Prediction}


def regenerate_docs(text: str) -> str:
    """docs/case-file.md's ``text`` with its settings tables written from :data:`DOCUMENTED_TABLES`."""
    return write_docs(text, DOCUMENTED_TABLES)


if __name__ == "__main__":                     # python -m livesweep.settings [docs/case-file.md]
    import sys

    page = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "docs" / "case-file.md")
    page.write_text(regenerate_docs(page.read_text(encoding="utf-8")), encoding="utf-8")
    print(f"{page}: settings tables regenerated")
