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

import os
import sys

from setuptools import setup
from setuptools.command.build_ext import build_ext

COMPILED = [
    "src/faultledger/domain/debounce.py",
    "src/faultledger/domain/events.py",
    "src/faultledger/domain/fault.py",
    "src/faultledger/domain/identity.py",
    "src/faultledger/domain/integrity.py",
    "src/faultledger/domain/notifications.py",
    "src/faultledger/domain/projector.py",
    "src/faultledger/domain/statistics.py",
    "src/faultledger/domain/transition.py",
    "src/faultledger/domain/types.py",
    "src/faultledger/service/event_ids.py",
    "src/faultledger/service/telemetry.py",
    "src/faultledger/service/writer.py",
    "src/faultledger/store/event_log.py",
    "src/faultledger/store/fastpath.py",
]
"""Keep in step with faultledger/compiled.py (MODULES), which tests compare with this list."""


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
    return list(mypycify([*options, *COMPILED], opt_level="3"))


setup(ext_modules=extensions(), cmdclass={"build_ext": BuildOrFallBack})
