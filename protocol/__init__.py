"""Wire formats of the SpiRob control stack: bytes <-> typed frames.

DBUS (DR16 receiver), C610/M2006 CAN frames, the host <-> board link and the MAVLink drone link, and
the host's end of the board link as a state machine (``protocol.session``).
No I/O and no clock live here: every function takes bytes (and, where framing needs it, a timestamp
in integer microseconds) and returns typed values.
"""
