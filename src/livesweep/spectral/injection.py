"""What an autopilot was told to inject: the band and schedule of a sweep it flies itself.

An autopilot that flies its own frequency sweep (ArduCopter's SystemID mode) knows exactly which
band it will cover and when each frequency is reached; so does the monitor, from the sweep's
parameters. A test point is then judged over the band the autopilot was told to sweep, and the
input counts as swept where the injection has had power so far (docs/method.md §2.5: "a frequency
counts as covered only after the sweep has passed it"), not against a baseline flown before the
test point, which may be a take-off or a loiter with its own manoeuvres.

ArduCopter's chirp (``AP_Math/chirp.cpp``, ``mode_systemid.cpp``), in chirp time
``tau = t - t_start - delay`` with ``t_start`` the "SystemID Starting" message and ``delay`` 1 s
(``SYSTEM_ID_DELAY``):

* ``tau <= t_const``: constant frequency ``w_min`` (two periods: ``t_const = 2 / f_start``);
* ``t_const < tau <= t_record``: ``w = w_min exp(B (tau - t_const) / (t_record - t_const))``,
  ``B = ln(w_max / w_min)``; the phase is its integral;
* a raised-cosine fade-in over the first ``t_fade_in`` and fade-out over the last ``t_fade_out``
  of ``t_record``; nothing after ``t_record``.

The parameters are ``SID_F_START_HZ``, ``SID_F_STOP_HZ``, ``SID_T_REC``, ``SID_T_FADE_IN``,
``SID_T_FADE_OUT`` and ``SID_MAGNITUDE`` (the DataFlash SIDS record carries them, with ``TC``,
at every start). Tests check the schedule against ArduPilot's own logged chirp (SIDD ``Targ``
and ``F``).

Pure: numbers in, a frozen :class:`SweepInjection` out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livesweep.errors import ConfigError

__all__ = ["SweepInjection", "ardupilot_chirp", "ARDUPILOT_SYSTEMID_DELAY_S"]

#: ArduCopter starts the chirp this long after "SystemID Starting" (``SYSTEM_ID_DELAY``) [s].
ARDUPILOT_SYSTEMID_DELAY_S = 1.0


@dataclass(frozen=True)
class SweepInjection:
    """An exponential frequency sweep injected on a known schedule.

    Attributes
    ----------
    omega_start_rad_s, omega_stop_rad_s : float
        The band the sweep was told to cover [rad/s].
    t_record_s : float
        Length of the sweep in chirp time, constant-frequency start included [s].
    t_const_s : float
        Time at the start frequency before the frequency rises [s].
    t_fade_in_s, t_fade_out_s : float
        Raised-cosine fades at either end [s].
    delay_s : float
        Chirp time 0 is this long after the test point's start [s].
    magnitude : float
        Amplitude (the autopilot's units: deg/s for a rate axis, deg for an angle axis).
    axis : int or None
        The autopilot's axis number (ArduCopter ``SID_AXIS``).
    source : str
        Where the parameters came from ("SIDS", "PARAM_VALUE").
    """

    omega_start_rad_s: float
    omega_stop_rad_s: float
    t_record_s: float
    t_const_s: float = 0.0
    t_fade_in_s: float = 0.0
    t_fade_out_s: float = 0.0
    delay_s: float = 0.0
    magnitude: float = 1.0
    axis: int | None = None
    source: str = ""

    def __post_init__(self):
        a, b = self.omega_start_rad_s, self.omega_stop_rad_s
        if not (math.isfinite(a) and math.isfinite(b) and 0 < a < b):
            raise ConfigError(f"sweep injection: band {a!r}-{b!r} rad/s must satisfy 0 < start < stop")
        for name in ("t_record_s", "t_const_s", "t_fade_in_s", "t_fade_out_s", "delay_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"sweep injection: {name} = {v!r} must be a finite number >= 0")
        if not self.t_record_s > self.t_const_s:
            raise ConfigError(f"sweep injection: t_record_s {self.t_record_s:g} must exceed t_const_s "
                              f"{self.t_const_s:g} (the sweep would never leave its start frequency)")

    @property
    def band_rad_s(self) -> tuple[float, float]:
        """(start, stop) [rad/s]."""
        return (self.omega_start_rad_s, self.omega_stop_rad_s)

    @property
    def duration_s(self) -> float:
        """From the test point's start to the end of the chirp's power [s]."""
        return self.delay_s + self.t_record_s

    def omega_at(self, elapsed_s) -> np.ndarray:
        """Instantaneous frequency [rad/s] at ``elapsed_s`` [s] after the test point's start
        (``omega_start`` before the sweep rises, ``omega_stop`` after it ends)."""
        tau = np.asarray(elapsed_s, float) - self.delay_s
        rise = self.t_record_s - self.t_const_s
        x = np.clip((tau - self.t_const_s) / rise, 0.0, 1.0)
        return self.omega_start_rad_s * np.exp(math.log(self.omega_stop_rad_s / self.omega_start_rad_s) * x)

    def swept_band(self, elapsed_s: float) -> tuple[float, float] | None:
        """The band the injection has had power in by ``elapsed_s`` [s] after the start [rad/s]:
        from its start frequency to the frequency it has reached; None before the chirp starts."""
        if elapsed_s <= self.delay_s:
            return None
        return (self.omega_start_rad_s, float(self.omega_at(elapsed_s)))

    def signal(self, elapsed_s) -> np.ndarray:
        """The injected signal at ``elapsed_s`` [s] after the start (ArduPilot's ``Chirp::update``)."""
        tau = np.asarray(elapsed_s, float) - self.delay_s
        rec, tc = self.t_record_s, self.t_const_s
        fi, fo = self.t_fade_in_s, self.t_fade_out_s
        window = np.ones_like(tau)
        if fi > 0:
            window = np.where(tau <= fi, 0.5 - 0.5 * np.cos(np.pi * np.clip(tau, 0, None) / fi), window)
        if fo > 0:
            window = np.where(tau > rec - fo, 0.5 - 0.5 * np.cos(np.pi * (tau - rec) / fo), window)
        w0 = self.omega_start_rad_s
        b = math.log(self.omega_stop_rad_s / w0)
        const = w0 * tau - w0 * tc
        rising = (w0 * (rec - tc) / b) * (np.exp(b * (tau - tc) / (rec - tc)) - 1.0)
        phase = np.where(tau <= tc, const, rising)
        out = window * self.magnitude * np.sin(phase)
        return np.where((tau > 0) & (tau <= rec), out, 0.0)

    def describe(self) -> str:
        """One line: the band in Hz and rad/s, the length and who asked for it."""
        lo, hi = self.band_rad_s
        who = f"axis {self.axis}, " if self.axis is not None else ""
        return (f"{lo / (2 * math.pi):.3g}-{hi / (2 * math.pi):.3g} Hz ({lo:.3g}-{hi:.3g} rad/s) in "
                f"{self.t_record_s:g} s ({who}{self.source or 'injection'})")

    def to_dict(self) -> dict:
        """The ``injection`` part of a ``/livesweep/test_point`` record."""
        return {"band_rad_s": [round(self.omega_start_rad_s, 6), round(self.omega_stop_rad_s, 6)],
                "t_record_s": self.t_record_s, "t_const_s": self.t_const_s, "t_fade_in_s": self.t_fade_in_s,
                "t_fade_out_s": self.t_fade_out_s, "delay_s": self.delay_s, "magnitude": self.magnitude,
                "axis": self.axis, "source": self.source}


def ardupilot_chirp(f_start_hz: float, f_stop_hz: float, t_record_s: float, *, t_fade_in_s: float = 0.0,
                    t_fade_out_s: float = 0.0, t_const_s: float | None = None, magnitude: float = 1.0,
                    axis: int | None = None, source: str = "") -> SweepInjection:
    """ArduCopter SystemID's chirp from its parameters (``SID_F_START_HZ``, ``SID_F_STOP_HZ``,
    ``SID_T_REC``, ``SID_T_FADE_IN``, ``SID_T_FADE_OUT``, ``SID_MAGNITUDE``).

    ``t_const_s`` defaults to two periods of the start frequency, as ArduCopter sets it
    (``time_const_freq = 2 / frequency_start``); the SIDS record logs it as ``TC``.

    Raises
    ------
    ConfigError
        Parameters that define no sweep (a start frequency not below the stop frequency, a record
        no longer than its constant-frequency start), naming the values.
    """
    try:
        f0, f1, rec = float(f_start_hz), float(f_stop_hz), float(t_record_s)
    except (TypeError, ValueError):
        raise ConfigError(f"SystemID parameters SID_F_START_HZ {f_start_hz!r}, SID_F_STOP_HZ {f_stop_hz!r}, "
                          f"SID_T_REC {t_record_s!r} are not numbers") from None
    if not (math.isfinite(f0) and math.isfinite(f1) and 0 < f0 < f1):
        raise ConfigError(f"SystemID parameters SID_F_START_HZ {f0:g}, SID_F_STOP_HZ {f1:g}: no sweep "
                          "(0 < start < stop needed)")
    tc = 2.0 / f0 if t_const_s is None else float(t_const_s)
    return SweepInjection(2 * math.pi * f0, 2 * math.pi * f1, rec, t_const_s=tc, t_fade_in_s=float(t_fade_in_s),
                          t_fade_out_s=float(t_fade_out_s), delay_s=ARDUPILOT_SYSTEMID_DELAY_S,
                          magnitude=float(magnitude), axis=axis, source=source)
