"""`make` installs the project while the interface packages build (Makefile, "setup").

That is safe only if the project's install changes nothing the ROS 2 wheels brought: every
package both sides need must be pinned in requirements-ros.txt exactly as in pyproject.toml.
Checked against the dependency tree pip actually installed in this venv.
"""

from __future__ import annotations

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PIN = re.compile(r"^\s*([A-Za-z0-9_.\-]+)\s*==\s*([^\s;#]+)")


def normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def pins(lines: list[str]) -> dict[str, str]:
    found = {}
    for line in lines:
        match = PIN.match(line)
        if match:
            found[normalized(match.group(1))] = match.group(2)
    return found


def ros_pins() -> dict[str, str]:
    return pins((ROOT / "requirements-ros.txt").read_text().splitlines())


def project_pins() -> dict[str, str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return pins(project["dependencies"])


def requirement_name(requirement: str) -> str | None:
    """The distribution a ``Requires-Dist`` line names, unless it is only for an extra."""
    if "extra ==" in requirement:
        return None
    match = re.match(r"\s*([A-Za-z0-9_.\-]+)", requirement)
    return normalized(match.group(1)) if match else None


def installed_closure(roots: list[str]) -> set[str]:
    """The ROS wheels and everything they require, as installed here."""
    seen: set[str] = set()
    todo = list(roots)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        try:
            requires = metadata.requires(name) or []
        except metadata.PackageNotFoundError:
            continue
        seen.add(name)
        todo.extend(n for r in requires if (n := requirement_name(r)) is not None)
    return seen


def test_shared_pins_agree() -> None:
    ros, project = ros_pins(), project_pins()
    shared = sorted(set(ros) & set(project))
    assert shared, "requirements-ros.txt pins none of the project's dependencies"
    assert {name: ros[name] for name in shared} == {name: project[name] for name in shared}


def test_every_package_both_need_is_pinned_for_ros() -> None:
    ros = ros_pins()
    if not any(name.startswith("ros-") for name in installed_closure(list(ros))):
        pytest.skip("the ROS 2 wheels are not installed in this venv (make setup)")
    needed_by_ros = installed_closure(list(ros))
    unpinned = sorted(name for name in set(project_pins()) & needed_by_ros if name not in ros)
    assert unpinned == [], (
        f"the ROS 2 wheels need {unpinned}, which pyproject.toml pins: pin them alike in "
        "requirements-ros.txt")
