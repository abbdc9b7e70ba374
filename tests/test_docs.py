"""The README and docs stay true: every scenario, parameter, CLI flag and benchmark is where users look.

The parameters: the docs' table, the host's parameter editor and the MAVLink types all say what the
firmware's parameter table (``controller.params``) says.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from controller.params import PARAMS, WIRE_ROWS, Kind, markdown
from hil.cli.main import build_parser as hil_parser
from hil.scenarios import SCENARIOS
from host.drone.params import PARAM_TYPES
from host.options import build_parser as host_parser
from host.panel.param_table import param_info
from protocol import mavlink as mav

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _flags(parser: argparse.ArgumentParser) -> set[str]:
    return {s for a in parser._actions for s in a.option_strings if s.startswith("--") and s != "--help"}


def test_readme_lists_every_scenario() -> None:
    listed = set(re.findall(r"^\| `([a-z-]+)` \|", README, re.M))
    assert set(SCENARIOS) <= listed, set(SCENARIOS) - listed
    hil_doc = (ROOT / "docs" / "hil.md").read_text(encoding="utf-8")
    assert all(f"`{name}`" in hil_doc for name in SCENARIOS)


def test_the_parameters_page_is_the_parameter_table() -> None:
    """docs/parameters.md is generated from controller.params: regenerate it when a row changes."""
    doc = (ROOT / "docs" / "parameters.md").read_text(encoding="utf-8")
    assert doc == markdown(), "docs/parameters.md is stale: python -m controller.params > docs/parameters.md"
    rows = re.findall(r"^\| (\d+) \| `([A-Z0-9_]+)` \|", doc, re.M)
    assert [(int(i), n) for i, n in rows] == list(enumerate(PARAMS))
    for page in ("board-link.md", "host.md", "mavlink.md"):
        assert "(parameters.md)" in (ROOT / "docs" / page).read_text(encoding="utf-8"), page


def test_editor_mavlink_types_and_docs_say_what_the_table_says() -> None:
    """The parameter editor's metadata, the MAVLink types and the docs' rows, parameter by parameter."""
    doc = (ROOT / "docs" / "parameters.md").read_text(encoding="utf-8")
    cells = {
        row[1].strip("` "): [c.strip() for c in row]
        for row in (line.split(" | ") for line in doc.splitlines() if re.match(r"^\| \d+ \| `", line))
    }
    mav_type = {
        Kind.BOOL: mav.ParamType.UINT8,
        Kind.INT: mav.ParamType.INT32,
        Kind.FLOAT: mav.ParamType.REAL32,
    }
    for name, row in WIRE_ROWS.items():
        info = param_info(name)
        assert (info.field, info.unit, info.kind, info.doc, info.safety) == (
            row.name,
            row.unit,
            row.kind.value,
            row.doc,
            row.safety,
        ), name
        assert info.default == float(row.default), name
        shown = row.runtime.text(row.unit) if row.runtime else row.bounds_text()
        assert info.bounds == shown, name
        assert PARAM_TYPES[name] == mav_type[row.kind], name
        index, _, field, kind, unit, _default, bounds, safe, meaning = cells[name]
        assert (int(index.strip("| ")), field, kind, unit) == (
            row.index,
            f"`{row.name}`",
            row.kind.value,
            row.unit,
        )
        assert bounds.startswith(row.bounds_text().removeprefix("must be ").removeprefix("in ")), name
        assert (safe == "yes") == row.safety and meaning.rstrip(" |").replace("\\|", "|") == row.doc, name
    assert set(cells) == set(PARAMS)


def test_readme_documents_every_spirob_host_flag() -> None:
    flags = _flags(host_parser())
    missing = {f for f in flags if f not in README}
    assert not missing, f"README does not mention spirob-host flags {sorted(missing)}"


def test_readme_names_every_spirob_hil_subcommand_and_benchmark() -> None:
    sub = next(a for a in hil_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert all(f"spirob-hil {name}" in README for name in sub.choices), sorted(sub.choices)
    benches = sorted(p.name for p in (ROOT / "bench").glob("*.py"))
    assert all(f"bench/{b}" in README for b in benches), benches


_OUTPUT_FLAGS = ("--record", "--report", "-o", "--out")
"""The flags through which a spirob-host or spirob-hil command writes files or directories."""


def test_readme_commands_write_under_runs_which_git_ignores() -> None:
    """A fresh clone stays clean: what the README's commands write goes under ``runs/`` (issue 25)."""
    commands = re.findall(r"^\.venv/bin/spirob-(?:host|hil) .*$", README, re.M)
    assert len(commands) > 10, commands
    outputs = []
    for command in commands:
        words = command.split("#")[0].split()
        outputs += [words[i + 1] for i, w in enumerate(words[:-1]) if w in _OUTPUT_FLAGS]
    assert len(outputs) >= 8, outputs
    elsewhere = [path for path in outputs if not path.startswith("runs/")]
    assert not elsewhere, elsewhere
    assert "mkdir -p runs" in README  # --record and -o need their directory; --report creates its own
    assert "/runs/" in (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()


def test_readme_links_resolve() -> None:
    for target in re.findall(r"\]\(([^)#]+)\)", README):
        if "://" not in target:
            assert (ROOT / target).exists(), target


_PACKAGES = ("protocol", "controller", "hil", "host")


def _names_in_backticks(text: str) -> set[str]:
    """Dotted names of the project's packages quoted in a page (``hil.sim.plant``, ``host.link.client``)."""
    pattern = r"`((?:" + "|".join(_PACKAGES) + r")(?:\.[A-Za-z_][A-Za-z0-9_]*)+)"
    return set(re.findall(pattern, text))


def _resolves(dotted: str) -> bool:
    """The longest prefix that is a module exists, and the rest names attributes of it."""
    import importlib

    parts = dotted.split(".")
    for n in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:n]))
        except ModuleNotFoundError:
            continue
        for attr in parts[n:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_the_architecture_page_names_only_what_exists_and_every_module() -> None:
    """docs/architecture.md: every dotted name it quotes resolves, and every module of the four packages is
    named there (by its dotted name, or by its last part in a row that groups a package's sections)."""
    doc = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    stale = sorted(n for n in _names_in_backticks(doc) if not _resolves(n))
    assert not stale, f"docs/architecture.md names what does not exist: {stale}"
    missing = []
    for package in _PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            if rel.name in ("__init__", "__main__") or rel.parts[:2] == ("hil", "scenarios"):
                continue
            dotted = ".".join(rel.parts)
            if f"`{dotted}`" not in doc and f"`{rel.name}`" not in doc and f"`{dotted}." not in doc:
                missing.append(dotted)
    assert not missing, f"modules docs/architecture.md does not describe: {missing}"
