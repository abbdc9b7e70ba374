"""The README and docs stay true: every scenario, parameter, CLI flag and benchmark is where users look."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from controller.params import PARAMS
from hil.cli.main import build_parser as hil_parser
from hil.scenarios import SCENARIOS
from host.options import build_parser as host_parser

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _flags(parser: argparse.ArgumentParser) -> set[str]:
    return {s for a in parser._actions for s in a.option_strings if s.startswith("--") and s != "--help"}


def test_readme_lists_every_scenario() -> None:
    listed = set(re.findall(r"^\| `([a-z-]+)` \|", README, re.M))
    assert set(SCENARIOS) <= listed, set(SCENARIOS) - listed
    hil_doc = (ROOT / "docs" / "hil.md").read_text(encoding="utf-8")
    assert all(f"`{name}`" in hil_doc for name in SCENARIOS)


def test_board_link_doc_lists_every_parameter() -> None:
    doc = (ROOT / "docs" / "board-link.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\d+) \| `([A-Z0-9_]+)` \|", doc, re.M)
    assert [(int(i), n) for i, n in rows] == list(enumerate(PARAMS))


def test_readme_documents_every_spirob_host_flag() -> None:
    flags = _flags(host_parser())
    missing = {f for f in flags if f not in README}
    assert not missing, f"README does not mention spirob-host flags {sorted(missing)}"


def test_readme_names_every_spirob_hil_subcommand_and_benchmark() -> None:
    sub = next(a for a in hil_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert all(f"spirob-hil {name}" in README for name in sub.choices), sorted(sub.choices)
    benches = sorted(p.name for p in (ROOT / "bench").glob("*.py"))
    assert all(f"bench/{b}" in README for b in benches), benches


def test_readme_links_resolve() -> None:
    for target in re.findall(r"\]\(([^)#]+)\)", README):
        if "://" not in target:
            assert (ROOT / target).exists(), target
