"""Hostile recordings: peak memory and time of every command that opens one, per crafted file.

Run: ``.venv/bin/python bench/recordings.py [--only NAME] [--records N] [--duration S]``. Writes each
crafted file of ``tests/support/hostile_mcap.py`` (zstd and lz4 bombs, chunks that inflate past what they
announce, huge record lengths, bad schemas, a cut file) and a long file of N small board-link records
(default 300,000, 1 ms apart, zstd chunks of 1000) into a temporary directory, then runs
``spirob-hil replay``, ``spirob-hil recover`` and ``spirob-host --replay --headless --duration S`` on each
in a fresh process and prints its exit status, peak RSS (``ru_maxrss`` of that process, from ``wait4``),
wall time and first stderr line. Targets (printed, not asserted): every peak under 300 MB, every refusal
one line with exit 2, and ``--duration`` held on the long file (wall time within S + 5 s).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# Running this file puts bench/ first on sys.path, where bench/protocol.py would shadow the `protocol`
# package: put the repository root in front.
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.hostile_mcap import CRAFTED, preamble, small_messages, zstd_chunk  # noqa: E402

TARGET_RSS_MB = 300.0
LONG = "long-small-records"


def _long_file(n: int) -> bytes:
    chunks = [zstd_chunk(small_messages(min(1000, n - k), k * 1_000_000)) for k in range(0, n, 1000)]
    return preamble() + b"".join(chunks)


def _measure(argv: list[str]) -> tuple[int, float, float, str]:
    """Exit status, peak RSS (MB) and wall time (s) of one process; its first stderr line."""
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = code = os.waitstatus_to_exitcode(status)
    lines = [line for line in err.splitlines() if line.strip()]
    return code, usage.ru_maxrss / 1024, time.monotonic() - t0, (lines[0] if lines else "")


def main(argv: list[str] | None = None) -> int:
    """Write the files, run the three commands on each, print one row per run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", metavar="NAME", help="one crafted file (or long-small-records)")
    parser.add_argument("--records", type=int, default=300_000, help="records of the long file (300000)")
    parser.add_argument("--duration", type=float, default=5.0, help="spirob-host --duration (5 s)")
    args = parser.parse_args(argv)
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        files: list[tuple[str, Path]] = []
        for c in CRAFTED:
            if args.only in (None, c.name):
                files.append((c.name, c.write(d)))
        if args.only in (None, LONG):
            path = d / f"{LONG}.mcap"
            path.write_bytes(_long_file(args.records))
            files.append((LONG, path))
        print(f"recordings: {len(files)} files, each through three commands in a fresh process")
        print(f"targets: peak RSS < {TARGET_RSS_MB:g} MB; refusals one line, exit 2; --duration held")
        head = f"{'file':<20} {'size':>9} {'command':<16} {'exit':>4} {'peak MB':>8} {'time s':>7}"
        print(head + "  first stderr line")
        worst = 0.0
        for name, path in files:
            commands = {
                "hil replay": [py, "-m", "hil.cli.main", "replay", str(path)],
                "hil recover": [py, "-m", "hil.cli.main", "recover", str(path), "-o", str(d / "out.mcap")],
                "host --replay": [
                    py, "-m", "host.cli", "--replay", str(path), "--headless",
                    "--duration", f"{args.duration:g}",
                ],
            }  # fmt: skip
            size = path.stat().st_size
            for label, cmd in commands.items():
                code, rss_mb, wall_s, line = _measure(cmd)
                worst = max(worst, rss_mb)
                note = line if len(line) <= 110 else line[:107] + "..."
                print(f"{name:<20} {size:>9} {label:<16} {code:>4} {rss_mb:>8.1f} {wall_s:>7.2f}  {note}")
                if name == LONG and label == "host --replay":
                    held = "held" if wall_s <= args.duration + 5.0 else "NOT held"
                    print(f"{'':<20} --duration {args.duration:g}: {held} ({wall_s:.1f} s in all)")
                (d / "out.mcap").unlink(missing_ok=True)
        verdict = "meets" if worst < TARGET_RSS_MB else "misses"
        print(f"largest peak RSS {worst:.1f} MB: {verdict} the {TARGET_RSS_MB:g} MB target")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
