"""Build hook: the per-record modules compiled to C with mypyc, on request.

Every report and every replayed record runs through the same few modules (the DEM state
machine, the statistics fold, the record codec, the group commit). Compiled, they cost about
a third less CPU (docs/architecture.md, "Compiled per-record modules"; docs/performance.md,
"Sixth round"); everything else, and all code that meets raw input, stays Python.
FAULTLEDGER_COMPILE=1 compiles them (``make compile``); the default install is plain Python,
because compiled code keeps the interpreter lock through long loops and a report then waits
behind a long statistics query (tests/ros/test_read_pool.py). Where compiling fails (no C
compiler) the install goes on in plain Python.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent


def compiled_sources() -> list[str]:
    """The source files of faultledger/compiled.py's MODULES, the one list of what is
    compiled (read from the file: the package itself cannot be imported while it builds)."""
    spec = importlib.util.spec_from_file_location(
        "faultledger_compiled", ROOT / "src" / "faultledger" / "compiled.py")
    assert spec is not None and spec.loader is not None
    listing = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(listing)
    return [f"src/{name.replace('.', '/')}.py" for name in listing.MODULES]


class BuildOrFallBack(build_ext):
    """A failed compile leaves the pure-Python modules in place instead of failing the
    install (the package is complete without the extensions)."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as error:  # no compiler, no Python headers
            print(f"faultledger: not compiled ({error}); installing pure Python",
                  file=sys.stderr)

    def build_extension(self, ext: object) -> None:
        try:
            super().build_extension(ext)
        except Exception as error:
            print(f"faultledger: {getattr(ext, 'name', ext)} not compiled ({error})",
                  file=sys.stderr)


def extensions() -> list[object]:
    if os.environ.get("FAULTLEDGER_COMPILE") != "1":
        return []
    try:
        from mypyc.build import mypycify
    except ImportError:
        print("faultledger: mypyc is not installed; installing pure Python", file=sys.stderr)
        return []
    # Its own mypy settings, not pyproject.toml's: the build environment has only the build
    # requirements (no pydantic for its plugin, no SQLAlchemy), so what the compiled modules
    # import from other packages is typed Any there, the same in every build.
    options = [f"--config-file={os.devnull}", "--ignore-missing-imports"]
    return list(mypycify([*options, *compiled_sources()], opt_level="3"))


setup(ext_modules=extensions(), cmdclass={"build_ext": BuildOrFallBack})
