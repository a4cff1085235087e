"""livesweep.spectral"""

#: The sliding window of the live estimate [s]: long enough for a few periods of a sweep's lowest
#: frequencies, short enough to follow the test point (the estimator's, the monitor's and the CLI's
#: default).
DEFAULT_WINDOW_S = 120.0
