"""The host's start-up error: one exception with a one-line reason."""

from __future__ import annotations

__all__ = ["HostError"]


class HostError(Exception):
    """A start-up failure with a one-line reason (printed, exit status 2)."""
