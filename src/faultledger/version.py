"""The installed version, for `--version`, the HTTP API's OpenAPI document and /health."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as package_version


def version() -> str:
    try:
        return package_version("faultledger")
    except PackageNotFoundError:  # a source tree that was never installed
        return "unknown"
