"""Build the ROS 2 interface packages in interfaces/ into a venv (the PyPI Jazzy wheels' prefix).

A package is skipped when the venv already holds a build of the same definitions (a stamp with
their sha256), or when no build of ours exists but the package is importable anyway (a sourced
ROS install provides it). Otherwise it is configured, built and installed with CMake.
Usage: python interfaces/build.py [--venv DIR] [--force] [PACKAGE ...]
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
PACKAGES = tuple(sorted(p.parent.name for p in HERE.glob("*/package.xml")))
"""Every package directory here; none depends on another of ours."""
SHARED = (HERE / "pypi_wheels_fix.cmake",)


def definition_hash(package: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted([*package.rglob("*"), *SHARED]):
        if path.is_file():
            digest.update(str(path.relative_to(HERE)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def stamp_path(venv: Path, name: str) -> Path:
    return venv / "share" / name / "faultledger-build.sha256"


def importable_elsewhere(name: str, venv: Path) -> str | None:
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        return None
    origin = Path(spec.origin).resolve()
    return None if venv.resolve() in origin.parents else str(origin.parent)


def build(package: Path, venv: Path) -> None:
    work = venv / "build" / "interfaces" / package.name
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = str(venv) + (
        os.pathsep + env["AMENT_PREFIX_PATH"] if env.get("AMENT_PREFIX_PATH") else "")
    python = venv / "bin" / "python3"
    steps = [
        ["cmake", "-S", str(package), "-B", str(work), *generator,
         "-DCMAKE_BUILD_TYPE=Release", "-DBUILD_TESTING=OFF",
         f"-DCMAKE_PREFIX_PATH={venv}", f"-DCMAKE_INSTALL_PREFIX={venv}",
         f"-DPython3_EXECUTABLE={python}"],
        ["cmake", "--build", str(work), "-j", str(os.cpu_count() or 2)],
        ["cmake", "--install", str(work)],
    ]
    for step in steps:
        result = subprocess.run(step, env=env, capture_output=True, text=True, check=False)
        if result.returncode != 0:
            sys.stderr.write(result.stdout[-4000:] + result.stderr[-4000:])
            raise SystemExit(f"interfaces: {package.name}: `{' '.join(step[:3])}` failed")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--venv", type=Path, default=Path(sys.prefix))
    parser.add_argument("--force", action="store_true", help="rebuild even when up to date")
    parser.add_argument("packages", nargs="*", default=list(PACKAGES))
    args = parser.parse_args()
    venv: Path = args.venv.resolve()
    if shutil.which("cmake") is None:
        raise SystemExit("interfaces: cmake is missing (apt-get install cmake g++ ninja-build)")
    for name in args.packages:
        package = HERE / name
        wanted = definition_hash(package)
        stamp = stamp_path(venv, name)
        have = stamp.read_text().strip() if stamp.is_file() else None
        if not args.force and have == wanted:
            print(f"interfaces: {name} up to date")
            continue
        elsewhere = importable_elsewhere(name, venv)
        if not args.force and have is None and elsewhere is not None:
            print(f"interfaces: {name} already importable from {elsewhere}; not building")
            continue
        started = time.monotonic()
        build(package, venv)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(wanted + "\n")
        print(f"interfaces: built {name} in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
