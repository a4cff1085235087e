"""livesweep.ident"""
