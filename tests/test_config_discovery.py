"""Commands run where `make run` runs find the shipped config/faultledger.yaml by themselves,
so `report-shift` and `stats` use the server's calendar (and zone) and e-stop codes; --config
and FAULTLEDGER_CONFIG still win, and without the file the built-in defaults apply."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

from faultledger import FaultLedger
from faultledger.domain.shifts import ShiftCalendar
from faultledger.service.config import DEFAULT_CONFIG, config_path, load_settings

ROOT = Path(__file__).resolve().parents[1]
PRESS = datetime(2026, 11, 21, 21, 30, tzinfo=UTC)  # 22:30 in Berlin: the night shift


def stats(db: Path, *args: str, env: dict[str, str] | None = None) -> list[dict[str, object]]:
    done = subprocess.run(
        [sys.executable, "-m", "faultledger.cli.main", "stats", "--by", "shift", "--json",
         "--db", str(db), "--since", "2026-11-21T20:00Z", "--until", "2026-11-22T02:00Z",
         "--as-of", "2026-11-22T02:00Z", *args],
        capture_output=True, text=True, timeout=60, check=False,
        env={**os.environ, **(env or {})})
    assert done.returncode == 0, done.stderr
    rows: list[dict[str, object]] = json.loads(done.stdout)
    return rows


def seed(db: Path) -> None:
    with FaultLedger.open(f"sqlite:///{db}", background=False) as ledger:
        assert ledger.report("HW_ARM_EMERGENCY_STOP", "FAILED", 3, "", "/arm", at=PRESS).accepted


def test_the_shipped_config_is_found_in_the_working_directory(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "config", Path.cwd() / "config")
    assert config_path(None) == DEFAULT_CONFIG
    shipped = load_settings(config_path(None))
    assert shipped.shifts == Path("config/shifts.yaml")
    assert shipped.estop_codes == ["HW_*_EMERGENCY_STOP"]
    db = tmp_path / "f.db"
    seed(db)
    rows = stats(db)
    # Berlin: the press at 22:30 local is in the night of the 21st; UTC shifts would put
    # 21:30Z in the afternoon.
    assert [(r["period"], r["estops"]) for r in rows if r["estops"]] == [
        ("2026-11-21/night", 1)]
    assert str(rows[0]["start"]).endswith("+00:00")


def test_an_explicit_config_wins_over_the_one_found(tmp_path: Path) -> None:
    shutil.copytree(ROOT / "config", Path.cwd() / "config")
    utc = tmp_path / "utc.yaml"
    utc.write_text("shifts: null\nestop_codes: [NOTHING_*]\n", encoding="utf-8")
    db = tmp_path / "f.db"
    seed(db)
    for rows in (stats(db, "--config", str(utc)),
                 stats(db, env={"FAULTLEDGER_CONFIG": str(utc)})):
        assert [r["period"] for r in rows if r["failed_reports"]] == ["2026-11-21/afternoon"]
        assert sum(int(str(r["estops"])) for r in rows) == 0


def test_without_a_config_file_the_built_in_defaults_apply(tmp_path: Path) -> None:
    assert config_path(None) is None
    db = tmp_path / "f.db"
    seed(db)
    rows = stats(db)
    assert [(r["period"], r["estops"]) for r in rows if r["failed_reports"]] == [
        ("2026-11-21/afternoon", 1)]


def test_the_calendar_summary_names_the_zone_and_the_shifts() -> None:
    calendar = ShiftCalendar.model_validate({"timezone": "Europe/Berlin", "shifts": [
        {"name": "early", "start": "05:00", "end": "13:30", "weekdays": ["mon", "tue"]},
        {"name": "night", "start": "22:00", "end": "05:00"}]})
    assert calendar.summary() == ("Europe/Berlin: early 05:00-13:30 (mon,tue), "
                                  "night 22:00-05:00")
