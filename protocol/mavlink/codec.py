"""The codec: our messages to MAVLink 2 packets and a received byte stream to packets, without I/O."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from protocol.mavlink.convert import from_pymavlink, to_pymavlink
from protocol.mavlink.dialect import SIGNING_KEY_LEN, dialect
from protocol.mavlink.messages import MavMessage, MavPacket

_MSG_ID_RADIO_STATUS: Final[int] = 109
_MSG_ID_RADIO: Final[int] = 166


class _Sink:
    """The file-like object pymavlink's ``MAVLink`` writes packed packets into."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.chunks.append(bytes(data))

    def take(self) -> bytes:
        data = b"".join(self.chunks)
        self.chunks.clear()
        return data


class MavCodec:
    """Encode our messages to MAVLink 2 packets and decode a received byte stream, without I/O.

    One codec per link: it owns the outgoing sequence number and the signing state. ``feed`` never
    raises on bad bytes; it counts them.

    Args:
        src_system: Our system id (1..255).
        src_component: Our component id (1..255).

    Attributes:
        packets_in: Well-formed packets decoded (including ``Unhandled`` ones).
        packets_out: Packets encoded.
        bytes_in: Bytes fed.
        malformed: Garbage runs, bad CRCs, bad lengths and undecodable payloads.
        unknown_ids: Packets whose message id the dialect does not know. They cannot be CRC-checked,
            so they are never delivered and their bytes are rescanned.
        signature_refused: Packets refused by signing (unsigned, wrong key or replayed).
        refused_by_msg_id: The same, by message id (at most 256 ids tracked).
    """

    def __init__(self, src_system: int, src_component: int) -> None:
        if not 1 <= src_system <= 255:
            raise ValueError(f"src_system out of range 1..255: {src_system}")
        if not 1 <= src_component <= 255:
            raise ValueError(f"src_component out of range 1..255: {src_component}")
        self._d = dialect()
        self._sink = _Sink()
        self._mav = self._d.MAVLink(self._sink, srcSystem=src_system, srcComponent=src_component)
        self._mav.robust_parsing = True  # bad bytes come back as BAD_DATA instead of raising
        self._allow_unsigned: Callable[[int], bool] = lambda _msg_id: False
        self.packets_in = 0
        self.packets_out = 0
        self.bytes_in = 0
        self.malformed = 0
        self.unknown_ids = 0
        self.signature_refused = 0
        self.refused_by_msg_id: dict[int, int] = {}

    @property
    def src_system(self) -> int:
        """Our system id."""
        return int(self._mav.srcSystem)

    @property
    def src_component(self) -> int:
        """Our component id."""
        return int(self._mav.srcComponent)

    # ---- signing -------------------------------------------------------------------------------

    def enable_signing(
        self,
        key: bytes,
        *,
        timestamp: int,
        link_id: int = 0,
        allow_unsigned: Callable[[int], bool] | None = None,
    ) -> None:
        """Sign every outgoing packet and refuse incoming ones that are not correctly signed.

        Args:
            key: The 32-byte secret key.
            timestamp: Initial signing timestamp (10 µs units since 2015; see
                :func:`signing_timestamp_from_unix_us`). Pass the larger of the clock and the last
                persisted value so it never goes backwards across restarts.
            link_id: Our signing link id (0..255).
            allow_unsigned: Decides, by message id, whether an unsigned or badly signed packet is
                accepted anyway. Default: only ``RADIO_STATUS`` and ``RADIO`` (from telemetry radios
                that cannot sign), as MAVProxy does.
        """
        if not isinstance(key, bytes) or len(key) != SIGNING_KEY_LEN:
            raise ValueError(f"signing key must be {SIGNING_KEY_LEN} bytes")
        if not 0 <= link_id <= 255:
            raise ValueError(f"link_id out of range 0..255: {link_id}")
        if timestamp < 0:
            raise ValueError("signing timestamp must be >= 0")
        self._allow_unsigned = allow_unsigned or (lambda mid: mid in (_MSG_ID_RADIO_STATUS, _MSG_ID_RADIO))
        s = self._mav.signing
        s.secret_key = key
        s.sign_outgoing = True
        s.link_id = link_id
        s.timestamp = int(timestamp)
        s.allow_unsigned_callback = self._unsigned_callback

    def disable_signing(self) -> None:
        """Stop signing and accept unsigned packets again."""
        s = self._mav.signing
        s.secret_key = None
        s.sign_outgoing = False
        s.allow_unsigned_callback = None
        s.link_id = 0

    @property
    def signing_enabled(self) -> bool:
        """True when a signing key is set."""
        return self._mav.signing.secret_key is not None

    @property
    def signing_timestamp(self) -> int:
        """The next outgoing signing timestamp (10 µs units since 2015); persist it to survive restarts."""
        return int(self._mav.signing.timestamp)

    def advance_signing_timestamp(self, timestamp: int) -> None:
        """Raise the signing timestamp to at least ``timestamp`` (it never goes backwards).

        Args:
            timestamp: A signing timestamp, typically from the clock.
        """
        s = self._mav.signing
        s.timestamp = max(int(s.timestamp), int(timestamp))

    @property
    def signatures_good(self) -> int:
        """Incoming packets whose signature verified."""
        return int(self._mav.signing.goodsig_count)

    @property
    def signatures_bad(self) -> int:
        """Incoming signed packets whose signature (key or timestamp) did not verify."""
        return int(self._mav.signing.badsig_count)

    def _unsigned_callback(self, _mav: Any, msg_id: int) -> bool:
        accepted = bool(self._allow_unsigned(int(msg_id)))
        if not accepted:
            self.signature_refused += 1
            if len(self.refused_by_msg_id) < 256 or msg_id in self.refused_by_msg_id:
                self.refused_by_msg_id[int(msg_id)] = self.refused_by_msg_id.get(int(msg_id), 0) + 1
        return accepted

    # ---- encode / decode -----------------------------------------------------------------------

    def encode(self, msg: MavMessage) -> bytes:
        """Pack one message as a MAVLink 2 packet (signed when signing is on).

        Advances the sequence number (and the signing timestamp when signing).

        Args:
            msg: Any message of our set except ``Unhandled``.

        Returns:
            The packet bytes.

        Raises:
            ValueError: A field is out of its wire range (names too long, non-ASCII, ...).
            TypeError: ``msg`` is not one of our messages.
        """
        m = to_pymavlink(self._d, msg)
        self._sink.take()
        self._mav.send(m)
        self.packets_out += 1
        return self._sink.take()

    def discard_partial(self) -> int:
        """Drop an incomplete packet held from earlier input (call at a datagram boundary).

        Over UDP every datagram holds whole packets, so leftovers are garbage; keeping them would let
        one truncated datagram swallow the first packet of the next.

        Returns:
            Bytes dropped (counted once as ``malformed`` when non-zero).
        """
        n = int(self._mav.buf_len())
        if n:
            self.malformed += 1
        self._reset_parser()
        return n

    def _rewind(self, data: bytes) -> None:
        mav_ = self._mav
        mav_.buf = bytearray(data) + mav_.buf[mav_.buf_index :]
        mav_.buf_index = 0
        mav_.expected_length = self._d.HEADER_LEN_V1 + 2

    def _reset_parser(self) -> None:
        self._mav.buf = bytearray()
        self._mav.buf_index = 0
        self._mav.expected_length = self._d.HEADER_LEN_V1 + 2

    def feed(self, data: bytes) -> list[MavPacket]:
        """Decode whatever complete packets ``data`` (plus earlier leftovers) holds.

        Never raises on bad bytes: garbage, bad CRCs and refused signatures are counted and skipped,
        and parsing resumes at the next start marker.

        Args:
            data: Bytes as they arrived (any split: half packets are kept for the next call).

        Returns:
            The good packets in arrival order.
        """
        self.bytes_in += len(data)
        out: list[MavPacket] = []
        signing = self._mav.signing
        chunk: bytes = bytes(data)
        # Each parse step consumes at least one byte for good (a rewind gives back all but the
        # first) or returns None, so this bounds the loop.
        for _ in range(len(data) + self._mav.buf_len() + 2):
            before = dict(signing.stream_timestamps) if signing.secret_key is not None else None
            try:
                m = self._mav.parse_char(chunk)
            except Exception:  # pymavlink may raise outside robust mode paths; never let it escape
                self.malformed += 1
                self._reset_parser()
                break
            chunk = b""
            if m is None:
                break
            mtype = m.get_type()
            if mtype == "BAD_DATA":
                reason = str(getattr(m, "reason", ""))
                if reason.startswith("Invalid signature"):
                    if before is not None:
                        signing.stream_timestamps = before  # see the package docstring
                    continue
                self.malformed += 1
                if reason != "Bad prefix" and len(m.data) > 1:
                    # A false start marker (or a damaged packet) made pymavlink swallow a whole
                    # "packet" of bytes, which may hold the start of a good one: rescan from the byte
                    # after the marker instead of dropping them.
                    self._rewind(bytes(m.data[1:]))
                continue
            if mtype.startswith("UNKNOWN_"):
                # pymavlink returns an unknown message id before checking the CRC (it has no CRC
                # extra for it), so this may be garbage that hides the start of a good packet:
                # count it, never deliver it, and rescan its bytes.
                self.unknown_ids += 1
                self._rewind(bytes(m.get_msgbuf())[1:])
                continue
            try:
                msg = from_pymavlink(m)
            except Exception:  # a field pymavlink accepted but we cannot represent
                self.malformed += 1
                continue
            self.packets_in += 1
            out.append(
                MavPacket(
                    msg,
                    int(m.get_srcSystem()),
                    int(m.get_srcComponent()),
                    int(m.get_seq()),
                    bool(m.get_signed()),
                    bytes(m.get_msgbuf()),
                )
            )
        return out


def decode_packets(data: bytes, codec: MavCodec | None = None) -> list[MavPacket]:
    """Decode a byte string with a fresh (or the given) codec; a convenience for tools and tests.

    Args:
        data: Concatenated packets.
        codec: Codec to use (its signing state applies); a new one (ids 255/190) if None.

    Returns:
        The good packets.
    """
    return (codec or MavCodec(255, 190)).feed(data)
