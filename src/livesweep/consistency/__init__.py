"""livesweep.consistency: data consistency and reconstruction before spectral analysis.

Pure numerical modules (arrays in, frozen results out; no I/O package is imported here):

- :mod:`livesweep.consistency.resample`: irregular, gappy signals onto one uniform grid,
  with every repair counted, and concatenation of records.
- :mod:`livesweep.consistency.wildpoints`: wild-point (spike) detection and repair.
- :mod:`livesweep.consistency.kinematics`: kinematic consistency checks and reconstruction.
"""
