"""MAVLink 2 signing helpers (pure: the caller reads files and clocks)."""

from __future__ import annotations

import hashlib

from protocol.mavlink.dialect import SIGNING_EPOCH_UNIX_S, SIGNING_KEY_LEN


def signing_key_from_passphrase(passphrase: str) -> bytes:
    """Return the 32-byte signing key for a passphrase, as MAVProxy derives it (SHA-256).

    Args:
        passphrase: The passphrase (MAVProxy takes ASCII; UTF-8 is used here).

    Returns:
        SHA-256 of the passphrase.
    """
    if not passphrase:
        raise ValueError("empty signing passphrase")
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def signing_key_from_file_bytes(data: bytes) -> bytes:
    """Interpret a key file's content: exactly 32 bytes is the raw key, anything else a passphrase.

    A passphrase file may end with a newline; surrounding whitespace is stripped before hashing.

    Args:
        data: The whole content of the key file.

    Returns:
        The 32-byte key.

    Raises:
        ValueError: The file is empty or its passphrase is not UTF-8.
    """
    if len(data) == SIGNING_KEY_LEN:
        return bytes(data)
    try:
        passphrase = data.decode("utf-8").strip()
    except UnicodeDecodeError as exc:
        raise ValueError("signing key file is neither 32 raw bytes nor a UTF-8 passphrase") from exc
    return signing_key_from_passphrase(passphrase)


def signing_timestamp_from_unix_us(unix_us: int) -> int:
    """Convert a Unix time in µs to a MAVLink signing timestamp (10 µs units since 2015-01-01).

    Args:
        unix_us: Microseconds since 1970-01-01 UTC.

    Returns:
        The signing timestamp (0 for times before 2015).
    """
    return max(0, (unix_us - SIGNING_EPOCH_UNIX_S * 1_000_000) // 10)
