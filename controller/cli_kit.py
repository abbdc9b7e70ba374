"""The conventions every command line of the project shares (``python -m controller``, ``spirob-hil``,
``spirob-host``).

- A user mistake (a bad flag, a bad combination, a port that cannot be opened) is **one line** on stderr,
  ``PROG: error: MESSAGE``, and exit status 2; never a usage dump, never a traceback.
- Exit statuses: :data:`EXIT_OK`, :data:`EXIT_FAILURE` (the run itself failed), :data:`EXIT_USAGE`,
  :data:`EXIT_INTERRUPTED` (Ctrl-C during a batch job, as a shell reports SIGINT: 128 + 2).
- Long-running servers stop cleanly on Ctrl-C and SIGTERM (:func:`stop_on_signals`); batch commands turn
  Ctrl-C into one ``interrupted`` line and status 130 (:func:`run_command`).
- Every command line answers ``--version`` with ``PROG VERSION``, the installed package's version
  (:func:`add_version`).
- The argument types check their value once, with the same wording everywhere (:func:`positive_duration`,
  :func:`seed`, :func:`port_number`).

This module sits in ``controller`` (the lowest package with a command line), so it imports nothing from
``hil`` or ``host``.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import NoReturn, TextIO

__all__ = [
    "EXIT_FAILURE",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_USAGE",
    "MAX_DURATION_S",
    "Parser",
    "UsageError",
    "add_version",
    "error_line",
    "finite_float",
    "package_version",
    "parse_or_exit",
    "port_number",
    "positive_duration",
    "run_command",
    "seed",
    "stop_on_signals",
    "writable_dir",
    "writable_file",
]

DISTRIBUTION = "spirob-teleop"
"""The installed distribution whose version ``--version`` prints."""

EXIT_OK = 0
EXIT_FAILURE = 1
"""The run itself failed (a scenario check, a replay mismatch, a board that died mid-run)."""
EXIT_USAGE = 2
"""A user mistake: bad flags, impossible values, a port or file that cannot be used."""
EXIT_INTERRUPTED = 130
"""Ctrl-C during a batch job, as a shell reports a process killed by SIGINT (128 + 2)."""


class UsageError(Exception):
    """A user mistake: reported as one line on stderr with exit status :data:`EXIT_USAGE`.

    Attributes:
        prog: the (sub)command it concerns, e.g. ``spirob-hil design``; None: the caller's program.
    """

    def __init__(self, message: str, prog: str | None = None) -> None:
        super().__init__(message)
        self.prog = prog


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors raise :class:`UsageError` (one line, no usage dump).

    Subparsers created with ``add_subparsers(parser_class=Parser)`` behave the same and name themselves
    in the error (``spirob-hil run: error: ...``).
    """

    def error(self, message: str) -> NoReturn:
        """Raise :class:`UsageError` instead of printing the usage and exiting."""
        raise UsageError(message, self.prog)


def package_version() -> str:
    """The installed ``spirob-teleop`` version (``importlib.metadata``); ``unknown`` in a bare checkout."""
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown"


def add_version(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Give ``parser`` a ``--version`` flag that prints ``PROG VERSION`` and exits 0; returns ``parser``."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    return parser


def error_line(prog: str | None, message: str, file: TextIO | None = None) -> None:
    """Print ``PROG: error: MESSAGE`` (or ``error: MESSAGE`` without a program) as exactly one line.

    Line breaks and runs of spaces in ``message`` become single spaces, so an exception from a library
    (python-can, pyserial, MuJoCo) still prints as one line.
    """
    text = " ".join(message.split()) or "invalid input"
    prefix = f"{prog}: error: " if prog else "error: "
    print(prefix + text, file=sys.stderr if file is None else file)


def parse_or_exit(
    parser: argparse.ArgumentParser, argv: Sequence[str] | None, hint: str = ""
) -> argparse.Namespace:
    """``parser.parse_args(argv)``; a :class:`UsageError` prints one line (``hint`` appended) and exits 2.

    For command lines that parse before they run (their ``--help`` and their usage errors end the
    process the way argparse's do).

    Raises:
        SystemExit: with :data:`EXIT_USAGE` on a usage error, or argparse's own status for ``--help``.
    """
    try:
        return parser.parse_args(argv)
    except UsageError as exc:
        error_line(exc.prog or parser.prog, f"{exc}{hint}")
        raise SystemExit(EXIT_USAGE) from None


def run_command(prog: str, body: Callable[[], int]) -> int:
    """Run a batch command's ``body`` and map what escapes it to one line and an exit status.

    :class:`UsageError` and ``ValueError`` (an impossible value found while running) give
    :data:`EXIT_USAGE`, and so does an ``OSError`` (a path the user gave that cannot be written, a full
    disk: the commands check their paths first, this is the backstop); Ctrl-C gives
    ``PROG: error: interrupted`` and :data:`EXIT_INTERRUPTED` (the ``with`` blocks on the way out have
    closed recordings and pools).
    """
    try:
        return body()
    except UsageError as exc:
        error_line(exc.prog or prog, str(exc))
    except ValueError as exc:
        error_line(prog, str(exc))
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        error_line(prog, f"{where}{exc.strerror or exc}")
    except KeyboardInterrupt:
        error_line(prog, "interrupted")
        return EXIT_INTERRUPTED
    return EXIT_USAGE


@contextmanager
def stop_on_signals(stop: threading.Event | None = None) -> Iterator[threading.Event]:
    """Within the block, Ctrl-C (SIGINT) and SIGTERM set ``stop`` (a fresh event if None) instead of
    interrupting: a server's loop polls it and shuts down in order. The previous handlers come back on
    exit. Outside the main thread (where Python cannot install handlers) nothing is installed.

    Yields:
        The event the signals set.
    """
    event = stop if stop is not None else threading.Event()
    previous: list[tuple[signal.Signals, object]] = []
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous.append((sig, signal.signal(sig, lambda *_: event.set())))
    try:
        yield event
    finally:
        for sig, handler in reversed(previous):
            signal.signal(sig, handler)  # type: ignore[arg-type]


# ---------------------------------------------------------------------- argument types


def finite_float(text: str) -> float:
    """A finite number (``nan`` and ``inf`` are refused here, once, rather than deep inside a run)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


MAX_DURATION_S = 1e9
"""The largest :func:`positive_duration` (about 31 years): its microseconds still fit the clocks' int64."""


def positive_duration(text: str) -> float:
    """A duration in seconds: a finite number > 0, at most :data:`MAX_DURATION_S` (``--duration``,
    ``--replay-speed``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    if value > MAX_DURATION_S:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_DURATION_S:g}, got {text!r}")
    return value


def seed(text: str) -> int:
    """A ``--seed``: a whole number >= 0 (numpy's seeds)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}")
    return value


def port_number(text: str) -> int:
    """A TCP/UDP port number, 0..65535 (0: any free port)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 0..65535: {text!r}")
    return value


# ---------------------------------------------------------------------- paths


def _probe_writable(directory: Path) -> None:
    """Create and delete a file in ``directory``: permission bits say nothing when running as root, and
    pseudo file systems (``/proc``, ``/sys``) refuse new files whatever the bits say."""
    with tempfile.TemporaryFile(dir=directory):
        pass


def writable_dir(path: Path, purpose: str, prog: str | None = None) -> Path:
    """Create the directory ``path`` (with its parents) for output and check a file can be written there.

    Called before a run starts, so a bad ``--report DIR`` costs no simulation. The error reads
    ``cannot PURPOSE PATH: REASON`` (``purpose`` e.g. ``"write plots into"``).

    Raises:
        UsageError: ``path`` is a file, cannot be created or takes no new files.
    """
    if path.exists() and not path.is_dir():
        raise UsageError(f"cannot {purpose} {path}: not a directory", prog)
    try:
        path.mkdir(parents=True, exist_ok=True)
        _probe_writable(path)
    except OSError as exc:
        raise UsageError(f"cannot {purpose} {path}: {exc.strerror or exc}", prog) from exc
    return path


def writable_file(path: Path, purpose: str, prog: str | None = None) -> Path:
    """Check the file ``path`` can be created (its directory exists and takes new files); nothing is written.

    The error reads ``cannot PURPOSE PATH: REASON`` (``purpose`` e.g. ``"record to"``).

    Raises:
        UsageError: ``path`` is a directory, its directory is missing or takes no new files.
    """
    if path.is_dir():
        raise UsageError(f"cannot {purpose} {path}: it is a directory", prog)
    if not path.parent.is_dir():
        raise UsageError(f"cannot {purpose} {path}: no such directory", prog)
    try:
        _probe_writable(path.parent)
    except OSError as exc:
        raise UsageError(f"cannot {purpose} {path}: {exc.strerror or exc}", prog) from exc
    return path
