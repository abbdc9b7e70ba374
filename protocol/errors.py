"""Exceptions of the protocol package.

Parsers that consume a byte stream (``DbusFramer``, ``LinkParser``) never raise on bad bytes: they
resynchronise and count. Exceptions are for single, already-framed payloads that cannot be decoded
(``DecodeError``) and for bad arguments (plain ``ValueError``).
"""

from __future__ import annotations

__all__ = ["DecodeError", "ProtocolError", "UnknownMessageError"]


class ProtocolError(Exception):
    """Base class of every exception raised by ``protocol``."""


class DecodeError(ProtocolError, ValueError):
    """A framed payload has the wrong length or a value outside its wire range.

    Also a ``ValueError``, so callers that only care about "bad input" can catch that.
    """


class UnknownMessageError(DecodeError):
    """A link frame carries a ``cmd_id`` that no message class is registered for."""
