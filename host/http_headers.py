"""Request headers a server checks before anything reads them: one ``Host``, one ``Origin``, well formed.

Shared by the panel's guard (:mod:`host.panel.guard`), the live Foxglove server's gate
(:mod:`host.foxglove_gate`) and ``--foxglove-origin`` (:mod:`host.options`). A duplicated header used to
raise inside the panel's check (``websockets`` refuses to pick one of two): HTTP 500 and a traceback.
"""

from __future__ import annotations

import re
import urllib.parse
from typing import Any

__all__ = ["header_problem", "normalise_origin"]

_HOST = r"(?:[A-Za-z0-9](?:[A-Za-z0-9.\-_]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\])(?::[0-9]{1,5})?"
_HOST_RE = re.compile(_HOST)
_ORIGIN_RE = re.compile(r"[A-Za-z][A-Za-z0-9+.\-]*://" + _HOST)


def _port_of(url: str) -> int | None:
    """The port of ``url`` (None without one, -1 when it is not in 0..65535)."""
    try:
        return urllib.parse.urlsplit(url).port
    except ValueError:
        return -1


def header_problem(headers: Any) -> str | None:
    """What is wrong with a request's ``Host`` and ``Origin`` headers (None: nothing).

    More than one of either, a ``Host`` that is not a host name or IP literal with an optional port in
    1..65535, or an ``Origin`` that is neither ``null`` nor ``scheme://host[:port]`` (no path). A missing
    header is not malformed (the Origin check decides about it).

    Args:
        headers: the request headers (``websockets.datastructures.Headers``: ``get_all``).
    """
    for name in ("Host", "Origin"):
        values = headers.get_all(name)
        if len(values) > 1:
            return f"{len(values)} {name} headers"
    for name, pattern in (("Host", _HOST_RE), ("Origin", _ORIGIN_RE)):
        values = headers.get_all(name)
        if not values or (name == "Origin" and values[0] == "null"):
            continue
        value = str(values[0])
        if not pattern.fullmatch(value) or _port_of(value if name == "Origin" else "//" + value) in (0, -1):
            return f"malformed {name} header {value[:80]!r}"
    return None


class _One:
    def __init__(self, name: str, value: str) -> None:
        self._name, self._value = name.lower(), value

    def get_all(self, name: str) -> list[str]:
        return [self._value] if name.lower() == self._name else []


def normalise_origin(origin: str) -> str:
    """An origin as browsers send it: lower-case, no trailing slash.

    Raises:
        ValueError: not ``scheme://host[:port]`` (a path, a query, spaces, no scheme, ``null``).
    """
    value = origin.strip().rstrip("/").lower()
    if value == "null" or header_problem(_One("Origin", value)) is not None:
        raise ValueError(f"not an origin (scheme://host[:port]): {origin!r}")
    return value
