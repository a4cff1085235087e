"""The numbers ``livesweep inspect`` judges a log by.

One job: the limits the other modules of :mod:`livesweep.inspection` share: how many fields a topic
lists, when a log is too short, how fast a signal must arrive for a band, the stream rate suggested
for a DataFlash log's telemetry, and how much of a test point a signal must cover.
"""

from __future__ import annotations

from livesweep.spectral.verdict import NYQUIST_FRACTION

__all__ = ["MAX_FIELDS", "SHORT_S", "RATE_PER_TOP_FREQUENCY", "STREAM_RATE_HZ", "COVER_FRACTION"]

#: Fields listed per topic at most (a DataFlash PARM or a ULog topic can have hundreds).
MAX_FIELDS = 40
#: A log shorter than this [s] is said to be too short for a frequency response.
SHORT_S = 10.0
#: A signal must arrive at this many times the top frequency it must show (2.5: the verdict judges
#: a signal up to NYQUIST_FRACTION = 0.8 of its Nyquist frequency, and one sampled slower aliases
#: what lies above).
RATE_PER_TOP_FREQUENCY = 2.0 / NYQUIST_FRACTION
#: The stream rate suggested for a DataFlash log's telemetry (``livesweep stream --rate-hz``; a
#: telemetry stream rate such as SRx_EXTRA1 = 50) [Hz].
STREAM_RATE_HZ = 50.0
#: Share of a SystemID test point (receive time) a signal's samples must span for it to count as
#: covered.
COVER_FRACTION = 0.9
