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
