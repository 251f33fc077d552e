"""The bench's errors: each names the input and what is wrong, so the CLI can print it without a traceback."""

from __future__ import annotations


class BenchError(Exception):
    """Base of every error the bench reports to a user as a one-line message."""


class ConfigError(BenchError):
    """A bad command-line value or configuration file."""


class DatabaseError(BenchError):
    """A DBC file that cannot be loaded or does not meet the bench's needs."""


class SignalError(BenchError):
    """A signal value that cannot be encoded (unknown name, NaN, out of range)."""


class LogError(BenchError):
    """A run log (MCAP) that cannot be written or read: missing, not MCAP, or bad data given to the recorder."""
