"""livesweep: frequency-response system identification for flight test.

Live sweep monitoring (MAVLink, Zenoh, Rerun, MCAP) and post-flight identification
following the frequency-response method of Tischler & Remple (CIFER).

The library face (each name loads its module on first use, so ``import livesweep`` stays light):

- :func:`identify` -- every stage of a case file, as one frozen :class:`Identification`;
  :func:`write_report` writes it to a folder (``report.json``, ``report.html``, plots).
- :func:`replay` -- the live monitor over an MCAP log, as ``livesweep replay`` runs it, as one frozen
  :class:`ReplayResult` (test points, verdicts, alerts as the recording's channels carry them).
- :func:`frequency_response` -- frequency responses from numpy arrays.
- :func:`fit_transfer_function` -- a transfer function fitted to one pair.
- :class:`StateSpaceModel` -- ``StateSpaceModel.from_matrices(...)`` or ``.from_table(...)``.
- Results convert to python-control: ``.to_frd()``, ``.to_tf()``, ``.to_ss()``.
"""

__version__ = "0.1.0"

_LAZY = {
    "identify": ("livesweep.stages.identify", "identify"),
    "Identification": ("livesweep.stages.identify", "Identification"),
    "STAGES": ("livesweep.stages", "STAGES"),
    "write_report": ("livesweep.report.writer", "write_report"),
    "replay": ("livesweep.monitor.session", "replay"),
    "ReplayResult": ("livesweep.monitor.session", "ReplayResult"),
    "frequency_response": ("livesweep.arrays", "frequency_response"),
    "fit_transfer_function": ("livesweep.arrays", "fit_transfer_function"),
    "StateSpaceModel": ("livesweep.ident.state_space", "StateSpaceModel"),
    "fit_state_space": ("livesweep.ident.state_space", "fit_state_space"),
    "FrequencyResponse": ("livesweep.spectral.response", "FrequencyResponse"),
    "FrequencyResponseSet": ("livesweep.spectral.response", "FrequencyResponseSet"),
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'livesweep' has no attribute {name!r}") from None
    import importlib

    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__():
    return sorted([*globals(), *_LAZY])
