"""Control inputs for the simulator: computer-generated sweeps, doublets, 3-2-1-1, steps, pilot noise.

Every signal is a frozen dataclass with a ``duration_s`` and a ``__call__(t)`` that returns the
deflection (input units, e.g. deg) at times ``t`` [s] measured from the start of the signal.
Signals are zero (trim) outside ``[0, duration_s]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from livesweep.errors import ConfigError, require_number

__all__ = [
    "FrequencySweep",
    "Doublet",
    "Multistep",
    "Step",
    "Trim",
    "PilotNoise",
]


def _finite_positive(name: str, value: float) -> float:
    return require_number(value, name, positive=True)


def _finite(name: str, value: float) -> float:
    return require_number(value, name)


@dataclass(frozen=True)
class FrequencySweep:
    """Computer-generated exponential frequency sweep with trim and fades (docs/method.md §2.3).

    Within the sweep (``0 <= t_s <= duration_s``, time since the end of the leading trim)::

        K(t)     = C2 (exp(C1 t / T) - 1)
        omega(t) = omega_min + K(t) (omega_max - omega_min)
        theta(t) = omega_min t + C2 (omega_max - omega_min) [ (T / C1)(exp(C1 t / T) - 1) - t ]
        delta(t) = A env(t) sin(theta(t))

    with C1 = 4, C2 = 0.0187 (so K(T) = 1.0023 and the sweep ends 0.2 % above omega_max) and
    ``env`` a raised-cosine fade-in over ``fade_in_s`` and fade-out over ``fade_out_s``.
    ``trim_s`` seconds of zero input precede and follow the sweep.

    Parameters
    ----------
    omega_min_rad_s, omega_max_rad_s : float
        Band of the sweep [rad/s]; ``0 < omega_min < omega_max``.
    duration_s : float
        Sweep length T [s], without the trims. Must cover two periods of ``omega_min``
        (the method's longest window needs two periods of the lowest frequency).
    amplitude : float
        A, in input units (deg); > 0.
    trim_s : float
        Quiescent trim before and after the sweep [s].
    fade_in_s, fade_out_s : float or None
        Raised-cosine fade lengths [s]. Defaults: half a period of ``omega_min`` (at most 10 %
        of T) and ``min(2, 0.05 T)``.
    c1, c2 : float
        Sweep-rate constants of the exponential schedule.
    """

    omega_min_rad_s: float
    omega_max_rad_s: float
    duration_s: float
    amplitude: float
    trim_s: float = 3.0
    fade_in_s: float | None = None
    fade_out_s: float | None = None
    c1: float = 4.0
    c2: float = 0.0187

    def __post_init__(self):
        wmin = _finite_positive("omega_min_rad_s", self.omega_min_rad_s)
        wmax = _finite_positive("omega_max_rad_s", self.omega_max_rad_s)
        if wmin >= wmax:
            raise ConfigError(f"omega_min_rad_s ({wmin:g}) must be below omega_max_rad_s ({wmax:g})")
        T = _finite_positive("duration_s", self.duration_s)
        shortest = 2.0 * 2.0 * math.pi / wmin
        if T < shortest:
            raise ConfigError(
                f"duration_s = {T:g} s is too short for omega_min_rad_s = {wmin:g}: "
                f"a sweep needs at least two periods of omega_min ({shortest:.1f} s)"
            )
        _finite_positive("amplitude", self.amplitude)
        if _finite("trim_s", self.trim_s) < 0:
            raise ConfigError(f"trim_s must be >= 0, got {self.trim_s!r}")
        for name in ("fade_in_s", "fade_out_s"):
            v = getattr(self, name)
            if v is not None and (_finite(name, v) < 0 or v > T / 2):
                raise ConfigError(f"{name} must be between 0 and duration_s/2 ({T / 2:g} s), got {v!r}")
        _finite_positive("c1", self.c1)
        _finite_positive("c2", self.c2)

    @property
    def fade_in(self) -> float:
        """Fade-in length actually used [s]."""
        if self.fade_in_s is not None:
            return float(self.fade_in_s)
        return min(math.pi / self.omega_min_rad_s, 0.1 * self.duration_s)

    @property
    def fade_out(self) -> float:
        """Fade-out length actually used [s]."""
        if self.fade_out_s is not None:
            return float(self.fade_out_s)
        return min(2.0, 0.05 * self.duration_s)

    @property
    def total_duration_s(self) -> float:
        """Trim + sweep + trim [s]."""
        return self.duration_s + 2.0 * self.trim_s


    def schedule(self, t_sweep) -> np.ndarray:
        """K(t) for times since sweep start [s] (dimensionless, 0 at t=0)."""
        t = np.asarray(t_sweep, dtype=float)
        return self.c2 * np.expm1(self.c1 * t / self.duration_s)

    def omega(self, t_sweep) -> np.ndarray:
        """Instantaneous frequency omega(t) [rad/s] for times since sweep start [s]."""
        return self.omega_min_rad_s + self.schedule(t_sweep) * (self.omega_max_rad_s - self.omega_min_rad_s)

    def phase(self, t_sweep) -> np.ndarray:
        """Sweep phase theta(t) = integral of omega [rad] for times since sweep start [s]."""
        t = np.asarray(t_sweep, dtype=float)
        T, c1, c2 = self.duration_s, self.c1, self.c2
        dw = self.omega_max_rad_s - self.omega_min_rad_s
        return self.omega_min_rad_s * t + c2 * dw * ((T / c1) * np.expm1(c1 * t / T) - t)

    def envelope(self, t_sweep) -> np.ndarray:
        """Raised-cosine fade envelope (0..1) for times since sweep start [s]."""
        t = np.asarray(t_sweep, dtype=float)
        env = np.ones_like(t)
        fi, fo, T = self.fade_in, self.fade_out, self.duration_s
        if fi > 0:
            m = t < fi
            env[m] = 0.5 * (1.0 - np.cos(np.pi * t[m] / fi))
        if fo > 0:
            m = t > T - fo
            env[m] = 0.5 * (1.0 - np.cos(np.pi * (T - t[m]) / fo))
        env[(t < 0) | (t > T)] = 0.0
        return env

    def __call__(self, t) -> np.ndarray:
        ts = np.asarray(t, dtype=float) - self.trim_s
        inside = (ts >= 0) & (ts <= self.duration_s)
        out = np.zeros_like(ts)
        out[inside] = self.amplitude * self.envelope(ts[inside]) * np.sin(self.phase(ts[inside]))
        return out


@dataclass(frozen=True)
class Multistep:
    """Multistep input: pulses of ``pattern[i] * unit_s`` seconds with alternating sign.

    ``pattern=(1, 1)`` is a doublet and ``(3, 2, 1, 1)`` the 3-2-1-1. ``trim_s`` of zero input
    precede and follow the pulses.

    Parameters
    ----------
    amplitude : float
        Pulse height in input units (deg); the sign of the first pulse. Non-zero.
    unit_s : float
        Length of one unit pulse [s].
    pattern : tuple of int
        Pulse lengths in units.
    trim_s : float
        Trim before and after [s].
    """

    amplitude: float
    unit_s: float
    pattern: tuple[int, ...] = (3, 2, 1, 1)
    trim_s: float = 2.0
    settle_s: float = 10.0

    def __post_init__(self):
        if _finite("amplitude", self.amplitude) == 0:
            raise ConfigError("amplitude must be non-zero")
        _finite_positive("unit_s", self.unit_s)
        if not self.pattern or any(int(p) <= 0 for p in self.pattern):
            raise ConfigError(f"pattern must be positive integers, got {self.pattern!r}")
        if _finite("trim_s", self.trim_s) < 0 or _finite("settle_s", self.settle_s) < 0:
            raise ConfigError("trim_s and settle_s must be >= 0")

    @property
    def total_duration_s(self) -> float:
        """Trim + pulses + settle [s]."""
        return self.trim_s + self.unit_s * sum(self.pattern) + self.settle_s


    def edges(self) -> np.ndarray:
        """Times of the pulse edges [s] from the start of the signal."""
        return self.trim_s + self.unit_s * np.concatenate([[0], np.cumsum(self.pattern)])

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        edges = self.edges()
        out = np.zeros_like(t)
        sign = 1.0
        for a, b in zip(edges[:-1], edges[1:]):
            out[(t >= a) & (t < b)] = sign * self.amplitude
            sign = -sign
        return out


def Doublet(amplitude: float, pulse_s: float, trim_s: float = 2.0, settle_s: float = 10.0) -> Multistep:
    """A doublet: +A for ``pulse_s``, then -A for ``pulse_s`` (a 1-1 multistep)."""
    return Multistep(amplitude=amplitude, unit_s=pulse_s, pattern=(1, 1), trim_s=trim_s, settle_s=settle_s)


@dataclass(frozen=True)
class Step:
    """A step of ``amplitude`` held for ``hold_s`` seconds after ``trim_s`` of trim, then released."""

    amplitude: float
    hold_s: float
    trim_s: float = 2.0
    settle_s: float = 5.0

    def __post_init__(self):
        if _finite("amplitude", self.amplitude) == 0:
            raise ConfigError("amplitude must be non-zero")
        _finite_positive("hold_s", self.hold_s)

    @property
    def total_duration_s(self) -> float:
        """Trim + hold + settle [s]."""
        return self.trim_s + self.hold_s + self.settle_s


    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        return np.where((t >= self.trim_s) & (t < self.trim_s + self.hold_s), float(self.amplitude), 0.0)


@dataclass(frozen=True)
class Trim:
    """Zero input for ``duration_s`` seconds."""

    duration_s: float

    def __post_init__(self):
        if _finite("duration_s", self.duration_s) < 0:
            raise ConfigError(f"duration_s must be >= 0, got {self.duration_s!r}")

    @property
    def total_duration_s(self) -> float:
        return float(self.duration_s)


    def __call__(self, t) -> np.ndarray:
        return np.zeros_like(np.asarray(t, dtype=float))


@dataclass(frozen=True)
class PilotNoise:
    """Small uncorrelated off-axis "pilot" input: Gaussian noise low-passed at ``bandwidth_rad_s``.

    Deterministic for a given ``seed`` and time grid. The output is scaled to ``rms`` exactly
    over the grid it is evaluated on.

    Parameters
    ----------
    rms : float
        Root-mean-square deflection (input units, deg); > 0.
    bandwidth_rad_s : float
        Corner of the 2nd-order Butterworth low-pass [rad/s].
    seed : int
        Random seed.
    """

    rms: float
    bandwidth_rad_s: float = 1.0
    seed: int = 0

    def __post_init__(self):
        _finite_positive("rms", self.rms)
        _finite_positive("bandwidth_rad_s", self.bandwidth_rad_s)

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if t.size < 2:
            return np.zeros_like(t)
        dt = float(np.median(np.diff(t)))
        fs = 1.0 / dt
        wc_hz = self.bandwidth_rad_s / (2 * np.pi)
        if wc_hz >= 0.5 * fs:
            raise ConfigError(f"bandwidth_rad_s {self.bandwidth_rad_s:g} is above the Nyquist frequency")
        rng = np.random.default_rng(self.seed)
        white = rng.standard_normal(t.size)
        sos = sps.butter(2, wc_hz, fs=fs, output="sos")
        x = sps.sosfiltfilt(sos, white)
        x -= x.mean()
        return self.rms * x / np.sqrt(np.mean(x**2))

