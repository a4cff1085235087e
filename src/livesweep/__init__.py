"""livesweep: frequency-response system identification for flight test.

Live sweep monitoring (MAVLink, Zenoh, Rerun, MCAP) and post-flight identification
following the frequency-response method of Tischler & Remple (CIFER).

The library face (each name loads its module on first use, so ``import livesweep`` stays light):

- :func:`identify` -- every stage of a case file, as one frozen :class:`Identification`;
  :func:`write_report` writes it to a folder (``report.json``, ``report.html``, plots).
- :func:`replay` -- the live monitor over an MCAP log, as ``livesweep replay`` runs it, as one frozen
  :class:`ReplayResult` (test points, verdicts, alerts as the recording's channels carry them).
- :func:`monitor` -- the live monitor on MAVLink and Zenoh links, as ``livesweep monitor`` runs it,
  in a background thread: a running :class:`Monitor` whose results grow as they come.
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
    "Monitor": ("livesweep.monitor.session", "Monitor"),
    "frequency_response": ("livesweep.arrays", "frequency_response"),
    "fit_transfer_function": ("livesweep.arrays", "fit_transfer_function"),
    "StateSpaceModel": ("livesweep.ident.state_space", "StateSpaceModel"),
    "fit_state_space": ("livesweep.ident.state_space", "fit_state_space"),
    "FrequencyResponse": ("livesweep.spectral.response", "FrequencyResponse"),
    "FrequencyResponseSet": ("livesweep.spectral.response", "FrequencyResponseSet"),
}

__all__ = ["__version__", "monitor", *_LAZY]


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
    return sorted({*globals(), "monitor", *_LAZY})


# ``livesweep.monitor`` is both the monitor's subpackage and the function that starts it: the
# package, once imported, is made callable (calling it calls livesweep.monitor.session.monitor),
# so ``livesweep.monitor(...)`` and ``import livesweep.monitor.pipeline`` both work in any order.
import sys as _sys
import types as _types


class _MonitorPackage(_types.ModuleType):
    """The ``livesweep.monitor`` package, callable as :func:`livesweep.monitor.session.monitor`."""

    def __call__(self, *args, **kwargs):
        import importlib

        return importlib.import_module("livesweep.monitor.session").monitor(*args, **kwargs)


class _Livesweep(_types.ModuleType):
    """The ``livesweep`` module: its ``monitor`` attribute is always the callable package."""

    @property
    def monitor(self):
        package = self.__dict__.get("_monitor_package")
        if package is None:
            import importlib

            package = importlib.import_module("livesweep.monitor")    # stored through the setter below
            package = self.__dict__.get("_monitor_package", package)
        return package

    @monitor.setter
    def monitor(self, package):
        if isinstance(package, _types.ModuleType) and package.__name__ == "livesweep.monitor":
            package.__class__ = _MonitorPackage
        self.__dict__["_monitor_package"] = package


_sys.modules[__name__].__class__ = _Livesweep
