"""Build the ROS 2 interface packages in interfaces/ into a venv (the PyPI Jazzy wheels' prefix).

A package is skipped when the venv already holds a build of the same definitions (a stamp with
their sha256), or when no build of ours exists but the package is importable anyway (a sourced
ROS install provides it). Otherwise it is configured, built and installed with CMake, --jobs
packages at a time (default 2, the heaviest first), each line of progress with its elapsed time.
Usage: python interfaces/build.py [--venv DIR] [--force] [--jobs N] [PACKAGE ...]
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path

HERE = Path(__file__).resolve().parent
PACKAGES = tuple(sorted(p.parent.name for p in HERE.glob("*/package.xml")))
"""Every package directory here; none depends on another of ours."""
SHARED = tuple(sorted(HERE.glob("*.cmake")))
"""CMake files every package includes: a change to one rebuilds them all."""


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


def weight(name: str) -> int:
    """How long a package takes to build, roughly: its number of .msg/.srv/.action files."""
    return sum(1 for p in (HERE / name).rglob("*") if p.suffix in {".msg", ".srv", ".action"})


_print_lock = threading.Lock()


def say(line: str) -> None:
    with _print_lock:
        print(f"interfaces: {line}", flush=True)


def build(package: Path, venv: Path, build_jobs: int) -> str:
    """Configure, build and install one package; returns the per-step timings."""
    work = venv / "build" / "interfaces" / package.name
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = str(venv) + (
        os.pathsep + env["AMENT_PREFIX_PATH"] if env.get("AMENT_PREFIX_PATH") else "")
    python = venv / "bin" / "python3"
    steps = [
        ("configure", ["cmake", "-S", str(package), "-B", str(work), *generator,
                       "-DCMAKE_BUILD_TYPE=Release", "-DBUILD_TESTING=OFF",
                       f"-DCMAKE_PREFIX_PATH={venv}", f"-DCMAKE_INSTALL_PREFIX={venv}",
                       f"-DPython3_EXECUTABLE={python}"]),
        ("build", ["cmake", "--build", str(work), "--parallel", str(build_jobs)]),
        ("install", ["cmake", "--install", str(work)]),
    ]
    timings = []
    for label, step in steps:
        started = time.monotonic()
        result = subprocess.run(step, env=env, capture_output=True, text=True, check=False)
        if result.returncode != 0:
            with _print_lock:
                sys.stderr.write(result.stdout[-4000:] + result.stderr[-4000:])
            raise SystemExit(f"interfaces: {package.name}: `{' '.join(step[:3])}` failed")
        timings.append(f"{label} {time.monotonic() - started:.0f} s")
    return ", ".join(timings)


def build_all(names: list[str], venv: Path, jobs: int, build_jobs: int,
              wanted: dict[str, str]) -> None:
    """Build ``names`` ``jobs`` at a time, heaviest first; a line when each starts and ends."""
    started_all = time.monotonic()
    order = sorted(names, key=weight, reverse=True)
    started: dict[str, float] = {}

    def one(name: str) -> str:
        started[name] = time.monotonic()
        say(f"building {name} ...")
        timings = build(HERE / name, venv, build_jobs)
        stamp = stamp_path(venv, name)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(wanted[name] + "\n")
        return timings

    pool = ThreadPoolExecutor(max_workers=jobs)
    futures: dict[Future[str], str] = {pool.submit(one, name): name for name in order}
    pending = set(futures)
    try:
        while pending:
            done, pending = wait(pending, timeout=20, return_when=FIRST_COMPLETED)
            for future in done:
                name = futures[future]
                timings = future.result()  # re-raises a failed build (SystemExit)
                say(f"built {name} in {time.monotonic() - started[name]:.0f} s ({timings})")
            running = [n for f in pending if (n := futures[f]) in started]
            if not done and running:
                now = time.monotonic()
                say("still building " + ", ".join(
                    f"{n} ({now - started[n]:.0f} s)" for n in sorted(running)))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)  # after a failure: start nothing new
    if len(names) > 1:
        say(f"{len(names)} packages built in {time.monotonic() - started_all:.0f} s "
            f"({jobs} at a time)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--venv", type=Path, default=Path(sys.prefix))
    parser.add_argument("--force", action="store_true", help="rebuild even when up to date")
    parser.add_argument("--jobs", type=int, default=2, help="packages built at a time (2)")
    parser.add_argument("--build-jobs", type=int, default=None,
                        help="`cmake --build --parallel` per package (default: cores)")
    parser.add_argument("packages", nargs="*", default=list(PACKAGES))
    args = parser.parse_args()
    venv: Path = args.venv.resolve()
    if shutil.which("cmake") is None:
        raise SystemExit("interfaces: cmake is missing (apt-get install cmake g++ ninja-build)")
    jobs = max(1, args.jobs)
    # Measured on 2 cores (docs/performance.md "First run"): 2 packages x 2 build jobs is
    # as fast as one at a time x 2 or faster (configure steps overlap); 2 x 1 was slower.
    build_jobs = args.build_jobs or (os.cpu_count() or 2)
    wanted: dict[str, str] = {}
    for name in args.packages:
        digest = definition_hash(HERE / name)
        stamp = stamp_path(venv, name)
        have = stamp.read_text().strip() if stamp.is_file() else None
        if not args.force and have == digest:
            say(f"{name} up to date")
            continue
        elsewhere = importable_elsewhere(name, venv)
        if not args.force and have is None and elsewhere is not None:
            say(f"{name} already importable from {elsewhere}; not building")
            continue
        wanted[name] = digest
    if wanted:
        build_all(list(wanted), venv, min(jobs, len(wanted)), build_jobs, wanted)
    return 0


if __name__ == "__main__":
    sys.exit(main())
