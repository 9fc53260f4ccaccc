"""A fleet central's reads on the command line (docs/fleet.md): `history --robot`, `verify
--robot`, `stats --group-by robot|line` and `--robot`, `list --robot`, as an operator runs them
against the central's database (a SQLite file here; the same code serves PostgreSQL)."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from faultledger import FaultLedger, Policy
from faultledger.service import fleet
from faultledger.store import fleet_log
from tests.fleet_central import run_cli
from tests.test_fleet_central import records_of, timed_robot_log

SINCE, UNTIL = "2026-11-20T00:00:00+00:00", "2026-11-21T06:00:00+00:00"
AS_OF = "2026-11-22T00:00:00+00:00"


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, dict[str, Path]]]:
    """A central holding two robots' logs, and the robots' own files."""
    root = tmp_path_factory.mktemp("site")
    robots = {name: root / f"{name}.db" for name in ("robot-a", "robot-b")}
    central = root / "central.db"
    with FaultLedger.open(f"sqlite:///{central}", policy=Policy(), robot_id="central",
                          background=False) as ledger, fleet.Fleet(ledger) as robot_logs:
        for seed, (name, path) in enumerate(robots.items()):
            robot_id, ledger_id, records = records_of(timed_robot_log(path, name, seed))
            robot_logs.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    yield central, robots


def cli(*args: str) -> str:
    done = run_cli(*args)
    assert done.returncode == 0, done.stderr + done.stdout
    return done.stdout


def test_history_of_a_robot_at_the_central_is_the_robots_own_export(
        site: tuple[Path, dict[str, Path]]) -> None:
    central, robots = site
    for name, path in robots.items():
        own = cli("history", "--db", str(path), "--format", "jsonl")
        held = cli("history", "--db", str(central), "--robot", name, "--format", "jsonl")
        assert held == own and own.count("\n") > 300
        csv_own = cli("history", "--db", str(path), "--csv", "--kind", "goal_outcome")
        assert cli("history", "--db", str(central), "--robot", name, "--csv", "--kind",
                   "goal_outcome") == csv_own
    table = cli("history", "--db", str(central), "--robot", "robot-a", "--limit", "3")
    assert "robot robot-a, log " in table


def test_verify_robot_passes_and_names_an_edit_of_the_centrals_copy(
        site: tuple[Path, dict[str, Path]], tmp_path: Path) -> None:
    central, _ = site
    out = cli("verify", "--db", str(central), "--robot", "robot-b")
    assert out.startswith("OK: robot robot-b, log ") and "projections equal a full replay" in out
    copy = tmp_path / "central.db"
    copy.write_bytes(central.read_bytes())
    chains = Path(f"{central}.fleet")
    (tmp_path / "central.db.fleet").mkdir()
    for file in chains.iterdir():
        (tmp_path / "central.db.fleet" / file.name).write_bytes(file.read_bytes())
    with FaultLedger.open(f"sqlite:///{copy}") as ledger, fleet.Fleet(ledger) as robot_logs:
        [chain] = robot_logs.chains("robot-b")
    path = Path(fleet_log.chain_url(f"sqlite:///{copy}", chain.chain_id).removeprefix(
        "sqlite:///"))
    with sqlite3.connect(path) as conn:
        seq = conn.execute("SELECT min(seq) FROM events WHERE kind = 'fault_reported'"
                           ).fetchone()[0]
        conn.execute("UPDATE events SET payload = replace(payload, '/base', '/bass') "
                     "WHERE seq = ?", (seq,))
    done = run_cli("verify", "--db", str(copy), "--robot", "robot-b")
    assert done.returncode == 1
    assert f"first bad seq: {seq}" in done.stdout and "robot robot-b" in done.stdout + done.stderr


def test_stats_per_robot_and_line_and_for_one_robot(site: tuple[Path, dict[str, Path]],
                                                     tmp_path: Path) -> None:
    central, robots = site
    config = tmp_path / "central.yaml"
    config.write_text(yaml.safe_dump({"fleet": {"robots": {
        "robot-a": {"line": "L3", "site": "S1"}, "robot-b": {"line": "L3", "site": "S1"}}}}))
    rows = json.loads(cli("stats", "--db", str(central), "--by", "day", "--since", SINCE,
                          "--until", UNTIL, "--as-of", AS_OF, "--group-by", "robot", "--json"))
    for name, path in robots.items():
        own = json.loads(cli("stats", "--db", str(path), "--by", "day", "--since", SINCE,
                             "--until", UNTIL, "--as-of", AS_OF, "--json"))
        mine = [{k: v for k, v in row.items() if k not in ("robot", "complete")}
                for row in rows if row["robot"] == name]
        assert mine == own
        assert all(row["complete"] is True for row in rows)
        alone = json.loads(cli("stats", "--db", str(central), "--by", "day", "--since", SINCE,
                               "--until", UNTIL, "--as-of", AS_OF, "--robot", name, "--json"))
        assert [{k: v for k, v in row.items() if k != "complete"} for row in alone] == own
    line = json.loads(cli("stats", "--db", str(central), "--config", str(config), "--by",
                          "day", "--since", SINCE, "--until", UNTIL, "--as-of", AS_OF,
                          "--group-by", "line", "--json"))
    assert {row["line"] for row in line} == {"L3"}
    assert sum(row["estops"] for row in line) == sum(row["estops"] for row in rows) > 0
    table = cli("stats", "--db", str(central), "--by", "day", "--since", SINCE, "--until",
                UNTIL, "--as-of", AS_OF, "--group-by", "robot")
    assert "robot-a" in table and "robot-b" in table and "e-stops" in table


def test_list_robot_and_an_unknown_robot(site: tuple[Path, dict[str, Path]]) -> None:
    central, robots = site
    for name, path in robots.items():
        own = json.loads(cli("list", "--db", str(path), "--all", "--json"))
        held = json.loads(cli("list", "--db", str(central), "--robot", name, "--all", "--json"))
        assert [{k: v for k, v in item.items() if k not in ("robot_id", "ledger_id")}
                for item in held] == own
        assert {item["robot_id"] for item in held} == {name}
    for command in (["list"], ["history"], ["verify"], ["stats"]):
        done = run_cli(*command, "--db", str(central), "--robot", "robot-z")
        assert done.returncode == 2, (command, done.stdout, done.stderr)
        assert "holds no robot robot-z; it holds robot-a, robot-b" in done.stderr
        assert done.stderr.count("\n") <= 2

