"""The modules the build compiles with mypyc (setup.py), and what keeps a checkout honest.

An editable install builds the compiled modules next to their sources. Edit a source and the
old compiled module would still be the one imported, silently running old code; so in a
checkout, when any compiled module is older than its source, all of them are removed at
import (they call one another directly, so it is all or none) and the sources run until
``make compile`` builds them again. An installed package is never touched.
"""

from __future__ import annotations

import sys
from importlib import machinery
from pathlib import Path

MODULES = (
    "faultledger.domain.debounce",
    "faultledger.domain.events",
    "faultledger.domain.fault",
    "faultledger.domain.identity",
    "faultledger.domain.integrity",
    "faultledger.domain.notifications",
    "faultledger.domain.projector",
    "faultledger.domain.statistics",
    "faultledger.domain.transition",
    "faultledger.domain.types",
    "faultledger.service.event_ids",
    "faultledger.service.telemetry",
    "faultledger.service.writer",
    "faultledger.store.event_log",
    "faultledger.store.fastpath",
)
"""What setup.py compiles (it reads this list; so does the Makefile's ``compile``)."""

_SOURCES = Path(__file__).resolve().parent.parent
"""The directory holding the ``faultledger`` package (``src`` in a checkout)."""


def _source(module: str) -> Path:
    return _SOURCES / (module.replace(".", "/") + ".py")


def built(module: str) -> list[Path]:
    """The compiled files of ``module`` beside its source (none: it runs as Python)."""
    source = _source(module)
    candidates = (source.with_name(source.stem + suffix)
                  for suffix in machinery.EXTENSION_SUFFIXES)
    return [path for path in candidates if path.exists()]


def active() -> list[str]:
    """The compiled modules this process runs (imported ones only)."""
    return [name for name in MODULES
            if name in sys.modules
            and not str(getattr(sys.modules[name], "__file__", "")).endswith(".py")]


def in_checkout() -> bool:
    return _SOURCES.name == "src" and (_SOURCES.parent / "pyproject.toml").is_file()


def stale() -> list[str]:
    """Compiled modules older than their source."""
    found = []
    for module in MODULES:
        try:
            changed = _source(module).stat().st_mtime
        except OSError:
            continue
        if any(path.stat().st_mtime < changed for path in built(module)):
            found.append(module)
    return found


def drop_stale() -> None:
    """In a checkout: remove every compiled module if one is older than its source."""
    if not in_checkout():
        return
    outdated = stale()
    if not outdated:
        return
    for module in MODULES:
        for path in built(module):
            path.unlink(missing_ok=True)
    print(f"faultledger: {', '.join(outdated)} changed since it was compiled; the compiled "
          "modules were removed and the sources run (make compile builds them again)",
          file=sys.stderr)
