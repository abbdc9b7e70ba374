#!/usr/bin/env bash
# One-time (and idempotent) set-up of a fresh machine for SpiRob Teleop.
#   scripts/setup.sh          Python environment in .venv (the product and its test tools)
#   scripts/setup.sh --system also the system packages the test suite drives for real:
#                             Debian's Chromium (browser tests) and tmux (MAVProxy tests)
set -euo pipefail
cd "$(dirname "$0")/.."

want_system=0
[ "${1:-}" = "--system" ] && want_system=1

say() { printf 'setup: %s\n' "$*" >&2; }

# --- system packages (apt-get; root or sudo) ------------------------------------------------------
if [ "$want_system" = 1 ]; then
    missing=()
    [ -x /usr/bin/chromium ] || missing+=(chromium)
    command -v tmux >/dev/null 2>&1 || missing+=(tmux)
    if [ "${#missing[@]}" -gt 0 ]; then
        SUDO=""
        [ "$(id -u)" = 0 ] || SUDO="sudo"
        say "installing ${missing[*]} with apt-get"
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
    fi
fi

# --- Python >= 3.11 and the project's virtual environment ------------------------------------------
PY=""
for cand in python3.13 python3.12 python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1 &&
        "$cand" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; then
        PY=$(command -v "$cand")
        break
    fi
done
[ -n "$PY" ] || { say "error: Python >= 3.11 is required"; exit 2; }

if [ ! -x .venv/bin/python ]; then
    say "creating .venv with $PY"
    "$PY" -m venv .venv
fi
stamp=.venv/.spirob-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    say "installing the project and its test tools into .venv (first run takes a few minutes)"
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e '.[test]'
    touch "$stamp"
fi
