"""The layers of docs/architecture.md, checked on every import in src/ (module level or not):
``domain`` ← ``store`` ← ``service`` ← ``reports`` ← adapters, and adapters only start one
another where the table below says so."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "faultledger"

RANK: dict[str, float] = {
    "domain": 0, "errors": 0, "version": 0,
    "compiled": 0,  # which modules the build compiles; imports nothing of the package
    "startup_heap": 0,  # the servers' gc.freeze(); imports nothing of the package
    "store": 1, "migrations": 1.5,  # Alembic scripts: they read store.schema
    "service": 2,
    "reports": 3,
    "cli": 4, "ros": 4, "http": 4, "nodemon": 4, "fleet": 4, "alerts": 4,
}
"""A part may import parts of a lower rank; same-rank imports need ADAPTER_EDGES."""

ADAPTER_EDGES = {
    ("cli", "ros"): "the CLI starts `serve`, `nodes` and the bridges",
    ("cli", "http"): "the CLI starts `faultledger http`",
    ("ros", "http"): "`serve --http` runs the HTTP API beside the node, over one ledger",
    ("nodemon", "ros"): "the heartbeat publisher is a ROS client",
    ("cli", "fleet"): "`faultledger sync`, `verify --central` and `http`'s fleet: push",
    ("ros", "fleet"): "`serve` pushes the log to a fleet central (the config's fleet:)",
    ("cli", "alerts"): "`faultledger http` delivers the config's alerts",
    ("ros", "alerts"): "`serve` delivers the config's alerts",
}


def part(module: str) -> str | None:
    """``faultledger.service.ledger`` -> ``service``; None for other packages."""
    names = module.split(".")
    if names[0] != "faultledger":
        return None
    return names[1] if len(names) > 1 else "<package>"


def imports() -> list[tuple[str, str, str]]:
    """(importing file, its part, imported module) for every faultledger import."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE)
        here = relative.parts[0].removesuffix(".py") if len(relative.parts) > 1 else (
            relative.stem)
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                found.append((str(relative), here, node.module))
            elif isinstance(node, ast.Import):
                found.extend((str(relative), here, alias.name) for alias in node.names)
    return found


def test_every_part_has_a_rank() -> None:
    parts = {p.name.removesuffix(".py") for p in PACKAGE.iterdir()
             if p.name != "__init__.py" and (p.suffix == ".py" or (p / "__init__.py").exists())}
    assert parts - set(RANK) == set()


def test_no_import_goes_up_or_across() -> None:
    wrong = []
    for path, here, module in imports():
        there = part(module)
        if there is None or there == here or here not in RANK:
            continue  # another package, the same part, or the package's own __init__
        if there == "<package>" or RANK[there] > RANK[here] or (
                RANK[there] == RANK[here] and (here, there) not in ADAPTER_EDGES):
            wrong.append(f"{path} imports {module}")
    assert wrong == []


def test_the_check_sees_imports_inside_functions() -> None:
    """serve's HTTP server and the shift-report route import lazily; both must be seen."""
    seen = {(path, module) for path, _, module in imports()}
    assert ("http/routes/stats.py", "faultledger.reports.shift") in seen
    assert ("cli/main.py", "faultledger.cli.nodes_view") in seen
