"""livesweep.report"""
