"""``livesweep inspect LOG``: what a log holds, the channel maps that fit it, its SystemID test points.

Any log livesweep reads, in one pass: a MAVLink ``.tlog`` frame by frame (no conversion); an MCAP
file directly (JSON channels decoded, other encodings counted and their fields listed from the
schema when it is a ROS message definition); a DataFlash ``.bin``, PX4 ``.px4log`` or ULog read
column-wise (only the records the SystemID texts and the vehicle's parameters need become Python
records); a table (it needs ``--columns``, as for ``convert``) converted to a temporary MCAP first.
For every topic: messages, rate, time span and numeric fields with their units (MAVLink's message
definitions, DataFlash FMTU, a column map's units). Then:

* **the shipped channel-map presets that fit**, best first: every signal's messages are there and
  vary, the vehicle is the one the map is made for (its ``[map.vehicle]`` against the log's
  parameters, "Frame:" text and HEARTBEAT type), and every signal arrives fast enough for the band
  the map's monitor judges: 2.5 x its top frequency (the band a SystemID run was told to sweep,
  else the map's; never above 0.8 of the map's grid Nyquist frequency, where the judged band ends).
  A signal's rate is the median of its samples per second on its own clock (its stamp field, the
  vehicle's time, when the map gives one: a ground station's bursty receive times do not count),
  over the SystemID runs when there are any. A preset whose signals are there but too slow is
  listed, in one line, with each slow message's rate against the rate needed;
* for an ArduCopter DataFlash log, the presets for its telemetry as ``livesweep stream`` sends it
  (the live path), at the stream rate suggested;
* **the ArduPilot SystemID test points**: each start ("SystemID Starting: axis=N" in STATUSTEXT or
  MSG, SIDS) with its axis, band and magnitude (from SIDS or the ``SID_*`` parameters) and its end
  ("SystemID Finished", or the mode leaving SYSTEMID). A test point is listed when the signals a
  preset needs for it (the input its axis sweeps and the outputs required with it) cover it at the
  rate its band needs; the others, announced by the autopilot but without such data (a log
  filtered around one run keeps the others' texts), are named in one line.

Progress: :func:`inspect_log` reports how far it has read through ``progress``;
:func:`stderr_progress` writes that to stderr for the command line.

Modules: :mod:`~livesweep.inspection.describe` (:func:`inspect_log`),
:mod:`~livesweep.inspection.readers` (one reader per log format), :mod:`~livesweep.inspection.stats`
(what the pass gathers), :mod:`~livesweep.inspection.fields` (fields and units),
:mod:`~livesweep.inspection.rates` (the rate a signal arrives at), :mod:`~livesweep.inspection.fits`
(the presets that fit), :mod:`~livesweep.inspection.runs` (the SystemID test points),
:mod:`~livesweep.inspection.text` (:func:`format_inspection`), :mod:`~livesweep.inspection.progress`
(:func:`stderr_progress`), :mod:`~livesweep.inspection.results` (the records returned) and
:mod:`~livesweep.inspection.thresholds` (the limits they share). Import from here.

This is an edge package (files); it only reads.
"""

from __future__ import annotations

from livesweep.inspection.describe import inspect_log
from livesweep.inspection.fields import (_ROS1_TIME, _ROS_NUMBERS, _ROS_PRIMITIVES, _ROS_TYPE, _channel_units,
                                         _mavlink_units, _numeric_fields, _ros_fields, _schema_fields)
from livesweep.inspection.fits import (_PID_RECORDS, _STREAM_OF_DATAFLASH, _band_top_hz, _candidate_maps, _fit,
                                       _judged_top_hz, _stream_rates)
from livesweep.inspection.progress import stderr_progress
from livesweep.inspection.rates import _CLOCK_BREAK_S, _arrival_rate, _rate, _signal_rate
from livesweep.inspection.readers import (_COUNT, _PLAIN, _PROGRESS_MESSAGES, _READ, _SYSID_PREFIX, _TICK,
                                          _read_dataflash, _read_mcap, _read_table, _read_tlog, _read_ulog, _sysid_of)
from livesweep.inspection.results import LogInspection, MapFit, SystemIdRun, TopicInfo
from livesweep.inspection.runs import _covers, _run_has_data, _run_signals, _runs
from livesweep.inspection.stats import _VEHICLE_TOPICS, _Frame, _key, _Signal, _Stats
from livesweep.inspection.text import _MAX_NAMED, _fields_line, format_inspection
from livesweep.inspection.thresholds import (COVER_FRACTION, MAX_FIELDS, RATE_PER_TOP_FREQUENCY, SHORT_S,
                                             STREAM_RATE_HZ)

__all__ = ["TopicInfo", "MapFit", "SystemIdRun", "LogInspection", "inspect_log", "format_inspection",
           "stderr_progress", "STREAM_RATE_HZ"]

#: Names of the modules above that are also importable from here.
_MOVED = (
    MAX_FIELDS, SHORT_S, RATE_PER_TOP_FREQUENCY, COVER_FRACTION,
    _ROS_NUMBERS, _ROS_PRIMITIVES, _ROS1_TIME, _ROS_TYPE, _numeric_fields, _mavlink_units, _channel_units,
    _ros_fields, _schema_fields,
    _STREAM_OF_DATAFLASH, _PID_RECORDS, _candidate_maps, _judged_top_hz, _band_top_hz, _fit, _stream_rates,
    _CLOCK_BREAK_S, _arrival_rate, _signal_rate, _rate,
    _PROGRESS_MESSAGES, _COUNT, _READ, _TICK, _PLAIN, _SYSID_PREFIX, _read_tlog, _read_dataflash, _read_ulog,
    _read_mcap, _sysid_of, _read_table,
    _run_signals, _covers, _run_has_data, _runs,
    _VEHICLE_TOPICS, _key, _Signal, _Stats, _Frame,
    _MAX_NAMED, _fields_line,
)
