"""`faultledger ack`, `shelve`, `unshelve`, and what `list`, `show` and `history` make of them,
run as a person runs them (real processes, a real SQLite file): exit codes, who is recorded,
the list's order and shelved view, and refusals that store nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

CLI = [sys.executable, "-m", "faultledger.cli.main"]


def run(db: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {key: value for key, value in os.environ.items() if key != "FAULTLEDGER_CONFIG"}
    return subprocess.run([*CLI, *args, "--db", str(db)], capture_output=True, text=True,
                          timeout=60, env={**env, "USER": "nightshift"})


def listed(db: Path, *args: str) -> list[dict[str, object]]:
    done = run(db, "list", "--json", *args)
    assert done.returncode == 0, done.stderr
    return list(json.loads(done.stdout))


def records(db: Path) -> int:
    done = run(db, "history", "--format", "jsonl")
    assert done.returncode == 0, done.stderr
    return len(done.stdout.splitlines())


def test_acknowledge_orders_the_list_and_a_new_episode_needs_another(tmp_path: Path) -> None:
    db = tmp_path / "faults.db"
    for code in ("A_MOTOR", "B_LIDAR", "C_BUMPER"):
        assert run(db, "report", code, "FAILED", "-s", "2", "--source", "/cell").returncode == 0
    done = run(db, "ack", "A_MOTOR", "--note", "replaced fuse")
    assert (done.returncode, done.stdout.strip()) == (0, "Fault acknowledged: A_MOTOR (episode 1)")
    assert [f["fault_code"] for f in listed(db)] == ["B_LIDAR", "C_BUMPER", "A_MOTOR"]
    ack = listed(db)[-1]["acknowledged"]
    assert isinstance(ack, dict) and (ack["by"], ack["note"]) == ("cli:nightshift",
                                                                  "replaced fuse")
    before = records(db)
    again = run(db, "ack", "A_MOTOR", "--actor", "dayshift")
    assert again.returncode == 0 and "already acknowledged by cli:nightshift" in again.stdout
    unknown = run(db, "ack", "Z_NONE")
    assert (unknown.returncode, unknown.stderr.strip()) == (1, "error: Fault not found: Z_NONE")
    bad = run(db, "ack", "A MOTOR")
    assert bad.returncode == 2 and "invalid character ' '" in bad.stderr
    assert records(db) == before  # none of them stored anything
    assert run(db, "clear", "A_MOTOR").returncode == 0
    late = run(db, "ack", "A_MOTOR")
    assert late.returncode == 1 and "CLEARED" in late.stderr
    assert run(db, "report", "A_MOTOR", "FAILED", "-s", "2", "--source", "/cell"
               ).returncode == 0
    shown = json.loads(run(db, "show", "A_MOTOR", "--json").stdout)
    assert shown["acknowledged"] is None and shown["episode"] == 2
    assert (shown["occurrences_in_episode"], shown["occurrences_total"]) == (1, 2)
    assert shown["first_occurred_ever"] < shown["first_occurred"]
    text = run(db, "show", "A_MOTOR").stdout
    assert "episode 2 since" in text and "not acknowledged" in text
    history = run(db, "history", "--code", "A_MOTOR").stdout
    assert "acknowledged by cli:nightshift" in history


def test_shelve_hides_a_fault_from_list_until_unshelved(tmp_path: Path) -> None:
    db = tmp_path / "faults.db"
    for code in ("DOCK_IR", "WHEEL_SLIP"):
        assert run(db, "report", code, "FAILED", "-s", "1", "--source", "/base").returncode == 0
    done = run(db, "shelve", "DOCK_IR", "--for", "1h30m", "--reason", "sun on the sensor")
    assert done.returncode == 0 and done.stdout.startswith("Fault shelved: DOCK_IR until ")
    assert [f["fault_code"] for f in listed(db)] == ["WHEEL_SLIP"]
    shelved = listed(db, "--shelved")
    assert [f["fault_code"] for f in shelved] == ["DOCK_IR"]
    assert shelved[0]["status"] == "CONFIRMED"  # status and counts go on
    assert "shelved" in run(db, "show", "DOCK_IR").stdout
    before = records(db)
    for args, message in ((("--for", "0s"), "more than 0 s"), (("--for", "45d"), "at most 30"),
                          (("--for", "soon"), "a duration is a number")):
        refused = run(db, "shelve", "WHEEL_SLIP", *args)
        assert refused.returncode == 2 and message in refused.stderr, refused.stderr
    assert records(db) == before
    assert run(db, "unshelve", "DOCK_IR", "--reason", "cleaned").returncode == 0
    assert [f["fault_code"] for f in listed(db)] == ["DOCK_IR", "WHEEL_SLIP"]
    twice = run(db, "unshelve", "DOCK_IR")
    assert twice.returncode == 1 and "not shelved" in twice.stderr
