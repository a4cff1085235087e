"""livesweep: frequency-response system identification for flight test.

Live sweep monitoring (MAVLink, Zenoh, Rerun, MCAP) and post-flight identification
following the frequency-response method of Tischler & Remple (CIFER).
"""

__version__ = "0.1.0"
