"""Exceptions that the command line turns into one-line messages and exit code 2."""


class LivesweepError(Exception):
    """A user-facing error: bad input, bad configuration or an unusable path.

    The message names what was wrong (file, key, value, channel or time) and is
    printed as one line by the CLI, without a traceback.
    """


class ConfigError(LivesweepError, ValueError):
    """A configuration value (case file, effect, sweep parameter) is invalid."""


class LogFormatError(LivesweepError):
    """A log file cannot be read or written as asked."""
