# The two commands of the README. Both set up a fresh machine first (scripts/setup.sh).
.PHONY: run test lint bench setup

run:
	@scripts/setup.sh
	.venv/bin/spirob-host

test:
	@scripts/setup.sh --system
	.venv/bin/ruff check .
	.venv/bin/ruff format --check .
	.venv/bin/mypy
	.venv/bin/python -m pytest -n 2 -m "not serial"
	.venv/bin/python -m pytest -m serial

lint:
	.venv/bin/ruff check .
	.venv/bin/mypy

bench:
	@scripts/setup.sh
	for b in bench/*.py; do .venv/bin/python $$b || exit 1; done

setup:
	@scripts/setup.sh --system
