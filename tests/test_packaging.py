"""Packaging: hg2prism installed with `pip install` (not editable) into a fresh Python 3.12 venv
works from any folder, and the installed package holds every subpackage, module and template.

Skipped, saying why, when there is no Python 3.12 on the machine or the package index cannot be
reached. It installs the dependencies at the versions of constraints.txt, so pip's cache makes
it quick after the first run (about 30-45 s; the first run downloads the wheels).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

import hg2prism
import reference
from conftest import MODELS, ROOT

TOL = 1e-6

PYTHON312_CANDIDATES = ("python3.12", "/root/.pyenv/versions/3.12.1/bin/python3.12")


def _python312() -> str | None:
    """A Python 3.12 interpreter that actually runs (a pyenv shim may exist without one)."""
    for candidate in PYTHON312_CANDIDATES:
        path = shutil.which(candidate) or (candidate if os.path.isfile(candidate) else None)
        if path is None:
            continue
        try:
            proc = subprocess.run([path, "-c", "import sys, venv; print(sys.version_info[:2])"],
                                  capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            continue
        if proc.returncode == 0 and proc.stdout.strip() == "(3, 12)":
            return path
    return None


def _source_copy(destination: Path) -> Path:
    """What a researcher's clone holds for installing, copied so that building leaves no trace
    (build/, *.egg-info) in the repository."""
    destination.mkdir()
    for name in ("pyproject.toml", "README.md", "constraints.txt"):
        shutil.copy2(ROOT / name, destination / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(ROOT / "hg2prism", destination / "hg2prism", ignore=ignore)
    shutil.copytree(ROOT / "templates", destination / "templates", ignore=ignore)
    return destination


def _run(command: list[str], cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bin folder of a fresh Python 3.12 venv with hg2prism pip-installed into it."""
    python = _python312()
    if python is None:
        pytest.skip("no Python 3.12 on this machine (looked for " + ", ".join(PYTHON312_CANDIDATES)
                    + ")")
    base = tmp_path_factory.mktemp("packaging")
    venv = base / "venv"
    proc = _run([python, "-m", "venv", str(venv)], cwd=base)
    assert proc.returncode == 0, proc.stderr
    bin_dir = venv / "bin"
    probe = _run([str(bin_dir / "pip"), "download", "--no-deps", "--only-binary=:all:",
                  "-d", str(base / "probe"), "-c", str(ROOT / "constraints.txt"), "stormpy"],
                 cwd=base, timeout=300)
    if probe.returncode != 0:
        pytest.skip("the package index cannot be reached: "
                    + (probe.stderr.strip().splitlines() or ["pip download failed"])[-1])
    source = _source_copy(base / "source")
    # --no-compile: the dependencies' bytecode is left to their first import (compiling all of
    # numpy, scipy, matplotlib and dask was a third of the install; what is imported is the same)
    proc = _run([str(bin_dir / "pip"), "install", "--quiet", "--no-compile", "-c",
                 str(source / "constraints.txt"), str(source)], cwd=base)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return bin_dir


def test_the_installed_package_has_every_module_and_template(installed: Path, tmp_path: Path) -> None:
    modules = sorted(str(p.relative_to(ROOT).with_suffix("")).replace(os.sep, ".")
                     .removesuffix(".__init__") for p in (ROOT / "hg2prism").rglob("*.py"))
    templates = sorted(p.name for p in (ROOT / "templates").glob("*.j2"))
    assert modules and templates
    script = (
        "import importlib, importlib.util, json, sys, hg2prism\n"
        "from importlib.resources import files\n"
        "files_of = {}\n"
        "for name in json.loads(sys.argv[1]):\n"
        "    # __main__ would run the command line: found, not imported\n"
        "    files_of[name] = (importlib.util.find_spec(name).origin if name.endswith('__main__')\n"
        "                      else importlib.import_module(name).__file__)\n"
        "templates = sorted(p.name for p in files('hg2prism.templates').iterdir()\n"
        "                   if p.name.endswith('.j2'))\n"
        "print(json.dumps({'version': hg2prism.__version__, 'files': files_of,\n"
        "                  'templates': templates, 'python': sys.version_info[:2]}))\n")
    proc = _run([str(installed / "python"), "-c", script, json.dumps(modules)], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout)
    assert found["python"] == [3, 12]
    assert found["version"] == hg2prism.__version__
    assert found["templates"] == templates
    assert sorted(found["files"]) == modules
    venv = installed.parent.resolve()
    for name, file in found["files"].items():
        # imported from the venv's site-packages, not from the repository
        assert Path(file).resolve().is_relative_to(venv), (name, file)


def test_the_installed_command_checks_world1_outside_the_repository(installed: Path,
                                                                     tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    world = elsewhere / "world1.toml"
    shutil.copy2(MODELS / "world1.toml", world)
    proc = _run([str(installed / "hg2prism"), "--version"], cwd=elsewhere)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"hg2prism {hg2prism.__version__}"

    proc = _run([str(installed / "hg2prism"), "check", "world1.toml", "--out", "out"],
                cwd=elsewhere)
    assert proc.returncode == 0, proc.stderr
    results = json.loads((elsewhere / "out" / "results.json").read_text())
    expected = reference.solve(MODELS / "world1.toml")
    assert abs(results["deceptive_value"] - expected.value) <= TOL
    assert abs(results["v_lead"] - expected.v_lead) <= TOL
    assert (results["states"], results["transitions"]) == (expected.states, expected.transitions)
    in_repo = hg2prism.solve(hg2prism.load_world(MODELS / "world1.toml"))
    assert abs(results["deceptive_value"] - in_repo.deceptive_value) <= 1e-10
    assert results["sound"] is True


def test_no_command_output_is_tracked_in_the_repository() -> None:
    """No output of a command is committed with the sources (a test run from the repository's
    root once wrote check's files there, and they were committed): no tracked file at the root
    or under models/ (where `make world1` writes) is named as a command's output."""
    import re

    from hg2prism.experiments.sweep import owned_pattern
    from hg2prism.outputs import MANIFEST, OWNED

    if not (ROOT / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout")
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.splitlines()
    output = re.compile("|".join(f"(?:{p})" for p in (*OWNED.values(), owned_pattern())))
    stray = [path for path in tracked if ("/" not in path or path.startswith("models/"))
             and (Path(path).name == MANIFEST or any(output.fullmatch(part)
                                                     for part in Path(path).parts))]
    assert stray == [], stray
