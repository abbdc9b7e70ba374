"""The package as a user installs it: a non-editable ``pip install .`` into a fresh virtual environment gives
working commands (``spirob-hil --version``, ``spirob-firmware --help``, ``spirob-host --help``), the DBC
and the LICENSE; every command line answers ``--version``.

The install never touches the network: pip builds the wheel from a copy of the sources with the build
backend of the environment running the tests (``--no-build-isolation --no-index``), then installs that
wheel into the fresh environment (``pip install .`` does the same two steps). The fresh environment sees
the dependencies of the running one through a ``.pth`` line written after the install, so nothing is
downloaded and the running environment's own (editable) spirob-teleop is never a candidate for pip.
"""

from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from collections.abc import Callable
from email.parser import HeaderParser
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

from controller.cli import main as firmware_main
from hil.cli.main import main as hil_main
from host.cli import main as host_main

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "controller", "hil", "host")
VERSION = importlib.metadata.version("spirob-teleop")
PIP = (sys.executable, "-m", "pip")


@pytest.mark.parametrize(
    ("main", "prog"),
    [(firmware_main, "python -m controller"), (hil_main, "spirob-hil"), (host_main, "spirob-host")],
)
def test_every_command_line_prints_its_version(
    main: Callable[[list[str]], int], prog: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"{prog} {VERSION}\n"


PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
CLASSIFIER_ROOTS = {
    "Development Status",
    "Environment",
    "Intended Audience",
    "Operating System",
    "Programming Language",
    "Topic",
    "Typing",
}


def test_metadata_has_classifiers_urls_and_keywords() -> None:
    classifiers = PROJECT["classifiers"]
    assert len(classifiers) >= 5 and len(set(classifiers)) == len(classifiers)
    for c in classifiers:
        parts = c.split(" :: ")
        assert len(parts) >= 2 and all(p.strip() == p and p for p in parts), c
        # No License classifier: PEP 639's `license` expression replaces it (setuptools >= 77 refuses both).
        assert parts[0] in CLASSIFIER_ROOTS, c
    assert any(c.startswith("Development Status :: ") for c in classifiers)
    assert any(c.startswith("Topic :: ") for c in classifiers)
    # The Python versions claimed are ones requires-python allows, and the one the suite runs on is one.
    requires = SpecifierSet(PROJECT["requires-python"])
    minors = [
        c.rsplit(" :: ", 1)[1] for c in classifiers if c.startswith("Programming Language :: Python :: 3.")
    ]
    assert minors and all(f"{m}.0" in requires for m in minors), minors
    assert f"{sys.version_info.major}.{sys.version_info.minor}" in minors
    urls = PROJECT["urls"]
    assert urls and all(url.startswith("https://") and " " not in url for url in urls.values()), urls
    keywords = PROJECT["keywords"]
    assert len(keywords) >= 5 and len(set(keywords)) == len(keywords)
    assert all(k == k.lower() and " " not in k for k in keywords), keywords


def test_the_mujoco_bound_is_the_tested_mujoco() -> None:
    (mujoco,) = (Requirement(d) for d in PROJECT["dependencies"] if Requirement(d).name == "mujoco")
    assert mujoco.extras == {"sysid"}
    installed = importlib.metadata.version("mujoco")
    # The version every figure and test was measured with is inside the bound; the next minor (whose
    # physics moved the pinned grasp outcomes) and the next major are outside it.
    assert installed in mujoco.specifier, (installed, str(mujoco.specifier))
    assert any(s.operator in ("<", "<=", "==", "~=") for s in mujoco.specifier), "mujoco has no upper bound"
    major, minor = (int(p) for p in installed.split(".")[:2])
    assert f"{major}.{minor + 1}.0" not in mujoco.specifier and f"{major + 1}.0.0" not in mujoco.specifier


def _run(argv: list[str], cwd: Path, timeout_s: float = 600.0) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PIP_")}
    env.update(PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_CACHE_DIR="1")
    return subprocess.run(
        argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s, check=False
    )


BUILD_BACKEND_MIN = (77,)
"""``[build-system] requires = ["setuptools>=77"]``: the PEP 639 ``license = "MIT"`` needs it."""


def test_a_non_editable_install_into_a_fresh_venv_gives_working_commands(tmp_path: Path) -> None:
    backend = importlib.metadata.version("setuptools")
    assert tuple(int(p) for p in backend.split(".")[:1]) >= BUILD_BACKEND_MIN, (
        f"building offline needs the build backend here: setuptools {backend} < 77 in {sys.prefix} "
        "(pip install 'setuptools>=77')"
    )
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    for package in PACKAGES:
        shutil.copytree(ROOT / package, src / package, ignore=shutil.ignore_patterns("__pycache__"))
    dist = tmp_path / "dist"
    built = _run(
        [*PIP, "wheel", "--no-deps", "--no-build-isolation", "--wheel-dir", str(dist), str(src)],
        cwd=tmp_path,
    )
    assert built.returncode == 0, built.stdout + built.stderr
    wheels = list(dist.glob("spirob_teleop-*.whl"))
    assert len(wheels) == 1, wheels
    # The metadata pyproject declares reaches the wheel (the build backend accepted every field).
    with zipfile.ZipFile(wheels[0]) as whl:
        (meta_name,) = (n for n in whl.namelist() if n.endswith(".dist-info/METADATA"))
        meta = HeaderParser().parsestr(whl.read(meta_name).decode())
    assert meta.get_all("Classifier") == PROJECT["classifiers"]
    assert sorted(meta.get_all("Project-URL") or []) == sorted(
        f"{k}, {v}" for k, v in PROJECT["urls"].items()
    )
    assert meta["Keywords"].split(",") == PROJECT["keywords"]

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    installed = _run(
        [*PIP, "--python", str(python), "install", "--no-deps", str(wheels[0])],
        cwd=tmp_path,
    )
    assert installed.returncode == 0, installed.stdout + installed.stderr
    site = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], cwd=tmp_path)
    fresh_site = Path(site.stdout.strip())
    (fresh_site / "spirob_test_deps.pth").write_text(sysconfig.get_path("purelib") + "\n", encoding="utf-8")

    # The packages and their data come from the fresh environment, not from this checkout.
    probe = _run(
        [
            str(python),
            "-c",
            "import importlib.metadata as m, importlib.resources as r, controller, host;"
            "print(controller.__file__); print(host.__file__);"
            "print(r.files('protocol').joinpath('c610.dbc').is_file());"
            "print(any(f.name == 'LICENSE' for f in m.files('spirob-teleop')))",
        ],
        cwd=tmp_path,
    )
    assert probe.returncode == 0, probe.stderr
    controller_file, host_file, has_dbc, has_license = probe.stdout.split()
    assert Path(controller_file).is_relative_to(fresh_site) and Path(host_file).is_relative_to(fresh_site)
    assert has_dbc == "True" and has_license == "True"

    scripts = venv / "bin"
    hil_version = _run([str(scripts / "spirob-hil"), "--version"], cwd=tmp_path)
    assert (hil_version.returncode, hil_version.stdout) == (0, f"spirob-hil {VERSION}\n"), hil_version.stderr
    firmware_help = _run([str(scripts / "spirob-firmware"), "--help"], cwd=tmp_path)
    assert firmware_help.returncode == 0, firmware_help.stderr
    assert firmware_help.stdout.startswith("usage: spirob-firmware")
    assert "--can-interface" in firmware_help.stdout
    host_help = _run([str(scripts / "spirob-host"), "--help"], cwd=tmp_path)
    assert host_help.returncode == 0 and host_help.stdout.startswith("usage: spirob-host"), host_help.stderr
    firmware_version = _run([str(scripts / "spirob-firmware"), "--version"], cwd=tmp_path)
    assert firmware_version.stdout == f"spirob-firmware {VERSION}\n", firmware_version.stderr
