"""Stages of `livesweep identify`: glue between the logs (I/O) and the numerical core."""
