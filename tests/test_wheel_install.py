"""An installed wheel works outside a checkout: the Alembic migrations ship inside the package.

Builds the project's wheel, installs it with ``pip --target`` into a scratch directory and runs
``db upgrade``, ``report`` and ``list`` from a directory that is not the checkout, on the base
interpreter with only that directory and the venv's site-packages (for the dependencies) on
``PYTHONPATH``, so neither ``src/`` nor the editable install can supply ``faultledger``.
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MIGRATION_FILES = ("env.py", "script.py.mako", "versions/0001_initial.py")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # Built from a copy of what goes into the wheel: nothing is written into the checkout.
    source = tmp_path_factory.mktemp("source")
    shutil.copy2(ROOT / "pyproject.toml", source)
    shutil.copy2(ROOT / "README.md", source)
    shutil.copytree(ROOT / "src", source / "src",
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.so"))
    out = tmp_path_factory.mktemp("wheelhouse")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
         "--disable-pip-version-check", "--quiet", "-w", str(out), str(source)],
        capture_output=True, text=True, timeout=180, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    (built,) = out.glob("faultledger-*.whl")
    return built


def test_the_wheel_holds_the_migrations(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    for name in MIGRATION_FILES:
        assert f"faultledger/migrations/{name}" in names
    shipped = {n for n in names if n.startswith("faultledger/migrations/versions/")}
    in_tree = {f"faultledger/migrations/versions/{p.name}"
               for p in (ROOT / "src/faultledger/migrations/versions").glob("*.py")}
    assert shipped == in_tree


def test_the_installed_wheel_runs_outside_the_checkout(wheel: Path, tmp_path: Path) -> None:
    target = tmp_path / "site"
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet",
         "--disable-pip-version-check", "--target", str(target), str(wheel)],
        capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stdout + done.stderr

    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in {"FAULTLEDGER_MIGRATIONS", "PYTHONHOME", "_ROS_WHEELS_BOOTSTRAP_COMPLETE"}}
    # The base interpreter does not read the venv's .pth files (editable install, ROS
    # bootstrapper): faultledger can only come from the wheel, the rest from the venv.
    env["PYTHONPATH"] = os.pathsep.join([str(target), *site.getsitepackages()])
    python = [getattr(sys, "_base_executable", sys.executable), "-s"]

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*python, *args], cwd=work, env=env, capture_output=True,
                              text=True, timeout=60, check=False)

    where = run("-c", "import faultledger; print(faultledger.__file__)")
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(target), where.stdout

    cli = ("-m", "faultledger.cli.main")
    db = "sqlite:///x.db"
    for args in (("db", "upgrade", "--db", db),
                 ("report", "MOTOR_OVERHEAT", "FAILED", "--severity", "ERROR",
                  "--source", "/motor", "--db", db),
                 ("list", "--all", "--db", db)):
        done = run(*cli, *args)
        assert done.returncode == 0, f"{args}: {done.stdout}{done.stderr}"
    assert "MOTOR_OVERHEAT" in done.stdout
    assert (work / "x.db").is_file()
    assert not (ROOT / "x.db").exists()
