"""livesweep.sim"""
