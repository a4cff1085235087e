"""Exceptions that the command line turns into one-line messages and exit code 2."""

import reprlib

_QUOTE = reprlib.Repr()
_QUOTE.maxstring = _QUOTE.maxother = 120
_QUOTE.maxlist = _QUOTE.maxtuple = _QUOTE.maxdict = _QUOTE.maxset = 8
_QUOTE.maxlevel = 3


class LivesweepError(Exception):
    """A user-facing error: bad input, bad configuration or an unusable path.

    The message names what was wrong (file, key, value, channel or time) and is
    printed as one line by the CLI, without a traceback.
    """


def quote(value) -> str:
    """``repr(value)`` cut to a line's worth, for messages that quote a value from a file (a
    crafted value can be megabytes long or nested thousands deep)."""
    return _QUOTE.repr(value)


class ConfigError(LivesweepError, ValueError):
    """A configuration value (case file, effect, sweep parameter) is invalid."""


class LogFormatError(LivesweepError):
    """A log file cannot be read or written as asked."""


def require_number(value, what: str, *, positive: bool = False, nonnegative: bool = False,
                   upper: float | None = None) -> float:
    """``value`` as a finite float, or ConfigError saying what is wrong with ``what``.

    Parameters
    ----------
    value : object
    what : str
        How the message names the value, e.g. ``"effect actuator_lag: time_constant_s"``.
    positive, nonnegative : bool
        Require ``> 0`` / ``>= 0``.
    upper : float, optional
        Require ``|value| <= upper``.
    """
    import math

    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ConfigError(f"{what} must be finite, got {value!r}")
    if positive and v <= 0:
        raise ConfigError(f"{what} must be > 0, got {value!r}")
    if nonnegative and v < 0:
        raise ConfigError(f"{what} must be >= 0, got {value!r}")
    if upper is not None and abs(v) > upper:
        raise ConfigError(f"|{what}| must be <= {upper:g}, got {value!r}")
    return v


def check_band(value, what: str, *, sample_rate_hz: float | None = None) -> tuple[float, float]:
    """A frequency band ``[low, high]`` [rad/s] as two floats, or ConfigError naming ``what``.

    The one definition of a valid band: two finite numbers with ``0 < low < high`` and, when the
    sample rate is given, ``high < pi * sample_rate_hz`` (Nyquist).

    Parameters
    ----------
    value : sequence of two numbers
    what : str
        How the message names the band, e.g. ``"case.toml: spectral.band_rad_s"``.
    sample_rate_hz : float, optional
        Sample rate [Hz] of the data the band applies to.

    Returns
    -------
    (float, float)
    """
    import math
    import numbers

    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ConfigError(f"{what} = {quote(value)}: must be [low, high], two numbers in rad/s")
    ends = []
    for k, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
            raise ConfigError(f"{what}[{k}] = {quote(v)}: must be a finite number [rad/s]")
        ends.append(float(v))
    lo, hi = ends
    if lo <= 0:
        raise ConfigError(f"{what} = {quote(value)}: the lower end must be > 0 rad/s")
    if lo >= hi:
        raise ConfigError(f"{what} = {quote(value)}: the lower end must be below the upper end")
    if sample_rate_hz is not None and hi >= math.pi * sample_rate_hz:
        raise ConfigError(f"{what} = {quote(value)}: the upper end must be below the Nyquist frequency "
                          f"pi * sample_rate_hz = {math.pi * sample_rate_hz:.6g} rad/s ({sample_rate_hz:g} Hz)")
    return lo, hi
