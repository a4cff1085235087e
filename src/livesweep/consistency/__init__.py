"""livesweep.consistency: data consistency and reconstruction before spectral analysis.

Pure numerical modules (arrays in, frozen results out; no I/O package is imported here):

- :mod:`livesweep.consistency.resample`: irregular, gappy signals onto one uniform grid,
  with every repair counted, and concatenation of records.
- :mod:`livesweep.consistency.wildpoints`: wild-point (spike) detection and repair.
- :mod:`livesweep.consistency.kinematics`: kinematic consistency checks and reconstruction.
"""

import numpy as _np

from livesweep.errors import ConfigError as _ConfigError


def usable_mask(signal, valid, what: str) -> _np.ndarray:
    """Samples that are finite and (when ``valid`` is given) marked valid; ConfigError naming
    ``what`` when the mask does not have the signal's shape."""
    mask = _np.isfinite(signal)
    if valid is not None:
        v = _np.asarray(valid)
        if v.shape != _np.shape(signal):
            raise _ConfigError(f"valid mask for {what} has shape {v.shape}, the signal has shape {_np.shape(signal)}")
        mask &= v.astype(bool)
    return mask
