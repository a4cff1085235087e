"""Whether the channel map fits what the link brings, said as ``map`` alerts.

:class:`MapCheck` is a part of :class:`~livesweep.monitor.pipeline.MonitorPipeline` (a mixin on its
state): ``DIAGNOSE_AFTER_S`` of receive time after the first frame it names every signal of the
map that found nothing, and why (an absent topic, a misspelt field, a selection nothing
matches); it says when such a signal is found later, and once that the vehicle is not the one
the map is made for. Driven by the frames' receive times, so a replay raises the same alerts at
the same data times as the live run did.
"""

from __future__ import annotations

import logging

from livesweep.spectral.excitation import Alert

__all__ = ["MapCheck", "DIAGNOSE_AFTER_S"]

log = logging.getLogger(__name__)

DIAGNOSE_AFTER_S = 5.0        # a map's signals that found nothing are named this long after the first frame [s of receive time]


class MapCheck:
    """The channel map against the link (mixin of :class:`~livesweep.monitor.pipeline.MonitorPipeline`,
    whose ``__init__`` sets the state these methods use: ``aligner``, ``names``, ``settings``,
    ``test_points``, ``map_problems`` and the check's private fields)."""

    def _map_check(self, receive_ns: int) -> None:
        """Diagnose the map DIAGNOSE_AFTER_S of receive time after the first frame; after that, watch
        for the signals it found missing. Driven by the frames' own receive times, so a replay
        raises the same ``map`` alerts at the same data times as the live run did."""
        if self.map_problems is None:
            if self._first_rx is None:
                self._first_rx = receive_ns
            elif receive_ns - self._first_rx >= DIAGNOSE_AFTER_S * 1e9:
                self._diagnose(receive_ns)
        else:
            self._map_found_later(receive_ns)

    def _diagnose(self, receive_ns: int) -> None:
        """Every signal of the map that found nothing, and why (an absent topic, a misspelt field, a
        selection nothing matches), as a ``map`` alert, a warning on stderr and ``map_problems``
        in the summary."""
        from livesweep.telemetry.extract import diagnose

        signals = {n: self.settings.signals[n] for n in self.names}
        self.aligner.settle_choice()
        self.map_problems = diagnose(signals, self.aligner.signal_counts, self._topics_seen)
        self._map_missing = [n for n in self.names if self.aligner.signal_counts[n]["samples"] == 0]
        if self.map_problems:
            self._drain_blocks()
        for line in self.map_problems:
            self._map_alert(line, receive_ns)

    def _map_found_later(self, receive_ns: int) -> None:
        """A signal the diagnosis found missing that has samples now (a vehicle that starts its
        streams once armed): say so, so the early warning does not stand."""
        found = [n for n in self._map_missing if self.aligner.signal_counts[n]["samples"] > 0]
        if found:
            self._drain_blocks()             # the alert's data time: every sample taken so far
        for n in found:
            self._map_missing.remove(n)
            left = len(self._map_missing)
            self._map_alert(f"signal {n}: found now ({'every signal found' if not left else f'{left} still missing'})",
                            receive_ns)

    def _map_alert(self, line: str, receive_ns: int) -> None:
        """A ``map`` alert, recorded at the receive time of the frame that raised it (not when a busy
        process got to write it), so its time says when the link showed the problem."""
        log.warning("monitor: %s", line)
        self._say_alert(self._t_data, Alert("map", line, 1.0), log_time_ns=receive_ns)

    def _check_vehicle(self, receive_ns: int) -> None:
        """Say once, as a ``map`` alert, that the vehicle is not the one the map is made for (its
        parameters, "Frame:" text or HEARTBEAT type contradict ``[map.vehicle]``); every test point
        from then on is NO-GO for it."""
        why = self.test_points.vehicle.contradiction(self.settings.vehicle)
        if why is None:
            return
        from livesweep.maps import presets_for

        self._unfit = self.test_points.unfit = why
        c, t = self.test_points.vehicle.frame()
        better = [n for n in presets_for(c, t, self.test_points.vehicle.mav_type) if n != self.settings.map_name]
        name = f"map {self.settings.map_name}" if self.settings.map_name else "the map"
        self._map_alert(f"{name} does not fit: {why}" + (f"; use {' or '.join(better)}" if better else ""),
                        receive_ns)
