"""livesweep.spectral"""
