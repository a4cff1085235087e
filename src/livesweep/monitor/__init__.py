"""livesweep.monitor"""
