"""livesweep.telemetry"""
