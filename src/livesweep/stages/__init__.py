"""Stages of `livesweep identify`: glue between the logs (I/O) and the numerical core."""

#: The identify stages in the order they run (``identify(until=...)``, ``livesweep identify --stage``).
STAGES = ("frequency-response", "transfer-functions", "state-space", "verification", "residual-loop")
