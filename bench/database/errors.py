"""The codec's errors, each also the class cantools raises for the same fault, so that code written against cantools
catches them. A module of their own: a compiled module (bench/compiled.py) cannot define a class that inherits from
builtin exceptions and cantools' at once, and bench/database/codec.py is compiled where a C compiler is present."""

from __future__ import annotations

import bitstruct
from cantools.database import errors as cantools_errors

from bench.errors import SignalError

__all__ = ["FIELD_OVERFLOW", "DecodeError", "EncodeError"]


class DecodeError(cantools_errors.DecodeError, ValueError):
    """A payload the database cannot decode (shorter than the message, an unknown multiplexer value).
    A cantools DecodeError too, so code written against cantools catches it."""


#: What cantools raises for a raw value its bit field cannot hold: bitstruct's C extension raises
#: OverflowError, the pure-Python bitstruct (cantools' fallback) raises bitstruct.Error.
FIELD_OVERFLOW: tuple[type[Exception], ...] = (OverflowError, bitstruct.Error)


# bitstruct ships no type information, so mypy sees its Error as Any (a base class it cannot check).
class EncodeError(SignalError, cantools_errors.EncodeError, OverflowError, bitstruct.Error):  # type: ignore[misc]
    """A value whose raw number does not fit its signal's bit field. It is each class cantools may raise
    for that (OverflowError or bitstruct.Error, by bitstruct build) and cantools' EncodeError, so a
    handler written for either catches it; a SignalError, so the bench reports it in one line."""
