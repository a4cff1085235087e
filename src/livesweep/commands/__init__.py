"""What each ``livesweep`` verb does and prints: one module per family of verbs.

- :mod:`~livesweep.commands.sim` -- ``sim``, ``stream`` (telemetry out: simulated or recorded)
- :mod:`~livesweep.commands.monitor` -- ``monitor``, ``replay`` (the live monitor, on links or a log)
- :mod:`~livesweep.commands.identify` -- ``identify``
- :mod:`~livesweep.commands.demo` -- ``demo``
- :mod:`~livesweep.commands.logs` -- ``convert``, ``inspect``, ``new-case``, ``recover``, ``maps``

Each command parses nothing itself (:mod:`livesweep.cli_parser` does) and computes nothing the
library does not: it calls the library and prints. ``batch`` lives in :mod:`livesweep.batch`.
"""
