"""Build hook: the per-record modules compiled to C with mypyc where a compiler is at hand.

Every report and every replayed record runs through the same few modules (the DEM state
machine, the statistics fold, the record codec, the group commit). Compiled, they cost about
a third less CPU (docs/architecture.md, "Compiled per-record modules"; docs/performance.md,
"Sixth round"); everything else, and all code that meets raw input, stays Python.
The compiled modules are the same source files, type-checked by mypy: nothing is written
twice. Set FAULTLEDGER_PURE_PYTHON=1 to install without compiling (a robot without a C
compiler gets the pure-Python package by itself: the build falls back when compiling fails).
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
    if os.environ.get("FAULTLEDGER_PURE_PYTHON") == "1":
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
