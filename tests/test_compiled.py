"""The per-record modules are compiled with mypyc where a compiler is at hand (setup.py), and
the same sources run as plain Python where not: both must behave the same, and a checkout
never runs a compiled module older than its source (faultledger/compiled.py)."""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from faultledger import compiled

ROOT = Path(__file__).resolve().parents[1]


def test_every_compiled_module_has_its_source_and_make_knows_it() -> None:
    """setup.py compiles MODULES; the Makefile's ``compile`` watches the same files."""
    sources = [f"src/{name.replace('.', '/')}.py" for name in compiled.MODULES]
    for source in sources:
        assert (ROOT / source).is_file(), source
    done = subprocess.run(["make", "-s", "--no-print-directory", "-f", "-", "show"],
                          input="include Makefile\nshow:\n\t@echo $(COMPILED_SOURCES)\n",
                          cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == sources


@pytest.mark.skipif(os.environ.get("FAULTLEDGER_PURE_PYTHON") == "1",
                    reason="installed without compiling (FAULTLEDGER_PURE_PYTHON=1)")
def test_this_checkout_runs_the_compiled_modules() -> None:
    """make setup-dev compiles them: the suite tests the code a deployment runs."""
    for name in compiled.MODULES:
        importlib.import_module(name)
    assert compiled.active() == list(compiled.MODULES)
    assert compiled.stale() == []


def copy_checkout(into: Path, with_compiled: bool) -> Path:
    """pyproject.toml and src/ (with or without the compiled files) in a scratch directory."""
    shutil.copy2(ROOT / "pyproject.toml", into / "pyproject.toml")
    ignored = ["__pycache__", "*.egg-info"] + ([] if with_compiled else ["*.so"])
    shutil.copytree(ROOT / "src", into / "src", ignore=shutil.ignore_patterns(*ignored),
                    copy_function=shutil.copy2)
    return into / "src"


def run_python(src: Path, code: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(src)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=120, check=False)


SHOW = ("import faultledger, faultledger.domain.projector as p, faultledger.compiled as c; "
        "print(p.__file__); print(len(c.active()))")


@pytest.mark.skipif(not compiled.built("faultledger.domain.projector"),
                    reason="this checkout is not compiled")
def test_a_source_edited_after_the_build_makes_the_checkout_run_the_sources(
        tmp_path: Path) -> None:
    src = copy_checkout(tmp_path, with_compiled=True)
    done = run_python(src, SHOW)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[0].endswith(".so")  # the copy runs compiled
    source = src / "faultledger" / "domain" / "debounce.py"
    later = time.time() + 5
    os.utime(source, (later, later))  # an edit after the build

    done = run_python(src, SHOW)
    assert done.returncode == 0, done.stderr
    assert "faultledger.domain.debounce changed since it was compiled" in done.stderr
    assert done.stdout.split("\n")[:2] == [str(src / "faultledger/domain/projector.py"), "0"]
    assert not list((src / "faultledger").rglob("*.so"))  # all of them, not only debounce
    again = run_python(src, SHOW)
    assert again.returncode == 0 and again.stderr == "", again.stderr  # said once


def test_an_installed_package_is_never_touched(tmp_path: Path) -> None:
    """Outside a checkout (no pyproject.toml beside src/) nothing is checked or removed."""
    src = copy_checkout(tmp_path, with_compiled=True)
    (tmp_path / "pyproject.toml").unlink()
    source = src / "faultledger" / "domain" / "debounce.py"
    later = time.time() + 5
    os.utime(source, (later, later))
    before = sorted((src / "faultledger").rglob("*.so"))
    done = run_python(src, SHOW)
    assert done.returncode == 0 and "changed since" not in done.stderr, done.stderr
    assert sorted((src / "faultledger").rglob("*.so")) == before


PURE_SUITES = ["tests/test_properties.py", "tests/test_stats_fold_staging.py",
               "tests/test_debounce_semantics.py", "tests/test_hostile_input.py",
               "tests/test_idempotency_and_concurrency.py"]
"""The state machine and restart == replay properties, the statistics fold, hostile input and
the group commit: what the compiled modules do, run once more on the sources alone."""


def test_the_sources_alone_pass_the_state_machine_and_replay_suites(tmp_path: Path) -> None:
    """A robot without a C compiler installs the pure-Python package: the same rules."""
    src = copy_checkout(tmp_path, with_compiled=False)
    env = {**os.environ, "PYTHONPATH": str(src)}
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
         *PURE_SUITES, "--override-ini", "addopts=",
         "-W", "ignore::pytest.PytestAssertRewriteWarning"],
        cwd=ROOT, capture_output=True, text=True, env=env, timeout=900, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert " passed" in done.stdout and " failed" not in done.stdout
    probe = run_python(src, SHOW)
    assert probe.stdout.split("\n")[:2] == [str(src / "faultledger/domain/projector.py"), "0"]
