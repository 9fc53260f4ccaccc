"""The dashboard in a real headless Chromium (Debian's chromium + chromium-driver): live
updates without reload, clearing with an operator token, a viewer refused, the statistics and
history views. Screenshots of every view land in
test-artifacts/screenshots/ (look at them)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.http.conftest import SHOTS, Server, needs_browser, start_server, write_config

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

pytestmark = needs_browser


def report(db: Path, code: str, event_type: str = "FAILED", severity: str = "3",
           description: str = "") -> None:
    subprocess.run([sys.executable, "-m", "faultledger.cli.main", "report", code, event_type,
                    "-s", severity, "-d", description, "--source", "/line3/cell",
                    "--db", str(db)], check=True, capture_output=True, timeout=60)


def wait(browser: WebDriver, condition: object, timeout: float = 10) -> None:
    WebDriverWait(browser, timeout, poll_frequency=0.05).until(condition)  # type: ignore[arg-type]


def row_status(browser: WebDriver, code: str) -> str | None:
    found = browser.execute_script(
        "const tr = document.querySelector(`#fault-table tr[data-code='${arguments[0]}']`);"
        "return tr ? tr.querySelector('.status').textContent : null;", code)
    return None if found is None else str(found)


def test_reports_appear_live_and_views_render(browser: WebDriver, tmp_path: Path) -> None:
    db = tmp_path / "f.db"
    report(db, "HW_BASE_EMERGENCY_STOP", description="e-stop pressed <b>on line 3</b>")
    report(db, "HW_BASE_EMERGENCY_STOP", "PASSED")
    server = start_server(db)
    try:
        browser.get(server.url)
        wait(browser, lambda b: b.find_element(By.ID, "connection").text == "live")
        page = browser.execute_script("return window.faultledgerPageId")
        started = time.monotonic()
        answer = server.client.post("/api/v1/reports", json={
            "fault_code": "DRIVE_OVERCURRENT", "event_type": "FAILED", "severity": 3,
            "description": "left wheel drive", "source_id": "/base/drive"})
        assert answer.json()["accepted"]
        wait(browser, lambda b: row_status(b, "DRIVE_OVERCURRENT") == "CONFIRMED", timeout=5)
        assert time.monotonic() - started < 1.0  # pushed by the stream, no polling
        assert browser.execute_script("return window.faultledgerPageId") == page  # no reload
        # Markup in a description is shown as text, never interpreted.
        browser.find_element(By.ID, "status-filter").send_keys("all")
        wait(browser, lambda b: row_status(b, "HW_BASE_EMERGENCY_STOP") is not None)
        assert "<b>on line 3</b>" in browser.find_element(By.ID, "fault-table").text
        browser.save_screenshot(str(SHOTS / "faults.png"))
        browser.find_element(By.CSS_SELECTOR, "tr[data-code='DRIVE_OVERCURRENT']").click()
        wait(browser, lambda b: len(b.find_elements(By.CSS_SELECTOR,
                                                    "#detail-history tbody tr")) >= 1)
        assert "CONFIRMED (active" in browser.find_element(By.ID, "detail-fields").text
        browser.save_screenshot(str(SHOTS / "fault-detail.png"))
        browser.find_element(By.CSS_SELECTOR, "button[data-view='stats']").click()
        browser.find_element(By.ID, "stats-shift").send_keys(current_shift())
        browser.find_element(By.CSS_SELECTOR, "#stats-form button[type='submit']").click()
        wait(browser, lambda b: b.find_elements(By.CSS_SELECTOR, "#figures .figure")
             and "in progress" in b.find_element(By.ID, "stats-title").text)
        keys = browser.execute_script(
            "return [...document.querySelectorAll('#figures .figure')].map(f => f.dataset.key)")
        assert keys[:2] == ["estops", "aborted_goals"]  # the report's order: e-stops first
        assert "e-stop" in browser.find_element(By.ID, "figures").text
        wait(browser, lambda b: len(b.find_elements(By.CSS_SELECTOR, "#offenders tbody tr")) >= 1)
        browser.save_screenshot(str(SHOTS / "statistics.png"))
        browser.find_element(By.CSS_SELECTOR, "button[data-view='history']").click()
        wait(browser, lambda b: len(b.find_elements(By.CSS_SELECTOR,
                                                    "#history-table tbody tr")) >= 4)
        browser.find_element(By.ID, "history-code").send_keys("HW_*")
        browser.find_element(By.CSS_SELECTOR, "#history-form button[type='submit']").click()
        wait(browser, lambda b: len(b.find_elements(By.CSS_SELECTOR,
                                                    "#history-table tbody tr")) == 2)
        browser.save_screenshot(str(SHOTS / "history.png"))
        browser.set_window_size(820, 1180)
        browser.find_element(By.CSS_SELECTOR, "button[data-view='faults']").click()
        browser.save_screenshot(str(SHOTS / "faults-tablet.png"))
        browser.set_window_size(1366, 900)
    finally:
        server.stop()


def current_shift() -> str:
    """The id of the default calendar's shift running now (UTC, three 8-hour shifts)."""
    from datetime import UTC, datetime

    from faultledger.domain.periods import default_calendar

    shift = default_calendar().shift_at(datetime.now(UTC))
    assert shift is not None
    return shift.id


def token(file: Path, name: str, role: str) -> str:
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "token", "create",
                           "--name", name, "--role", role, "--file", str(file)],
                          capture_output=True, text=True, timeout=60, check=True)
    return done.stdout.strip()


def sign_in(browser: WebDriver, server: Server, value: str) -> None:
    browser.get(server.url)
    browser.execute_script("sessionStorage.clear()")
    browser.get(server.url)
    wait(browser, lambda b: b.find_element(By.ID, "token-form").is_displayed())
    browser.find_element(By.ID, "token-input").send_keys(value)
    browser.find_element(By.CSS_SELECTOR, "#token-form button").click()
    wait(browser, lambda b: b.find_element(By.ID, "connection").text == "live")


def test_an_operator_clears_from_the_page_and_a_viewer_cannot(browser: WebDriver,
                                                              tmp_path: Path) -> None:
    db = tmp_path / "f.db"
    tokens = tmp_path / "tokens.yaml"
    viewer, operator = token(tokens, "screen", "viewer"), token(tokens, "shift-lead", "operator")
    report(db, "GRIPPER_JAM", description="gripper jammed")
    server = start_server(db, config=write_config(tmp_path / "c.yaml",
                                                  http={"tokens_file": str(tokens)}))
    try:
        sign_in(browser, server, viewer)
        wait(browser, lambda b: row_status(b, "GRIPPER_JAM") == "CONFIRMED")
        browser.find_element(By.CSS_SELECTOR, "tr[data-code='GRIPPER_JAM']").click()
        wait(browser, lambda b: b.find_element(By.ID, "clear-form").is_displayed())
        browser.find_element(By.CSS_SELECTOR, "#clear-form button").click()
        wait(browser, lambda b: "may not clear faults" in b.find_element(
            By.ID, "clear-message").text)
        browser.save_screenshot(str(SHOTS / "viewer-refused.png"))
        assert row_status(browser, "GRIPPER_JAM") == "CONFIRMED"
        sign_in(browser, server, operator)
        browser.find_element(By.CSS_SELECTOR, "tr[data-code='GRIPPER_JAM']").click()
        wait(browser, lambda b: b.find_element(By.ID, "clear-form").is_displayed())
        browser.find_element(By.ID, "clear-reason").send_keys("jam removed")
        browser.find_element(By.CSS_SELECTOR, "#clear-form button").click()
        wait(browser, lambda b: row_status(b, "GRIPPER_JAM") is None, timeout=5)  # left the view
        cleared = server.client.get("/api/v1/history", params={"kind": "fault_cleared"},
                                    headers={"Authorization": f"Bearer {operator}"}).json()
        assert cleared["items"][0]["payload"]["actor"] == "shift-lead"
        assert cleared["items"][0]["payload"]["reason"] == "jam removed"
    finally:
        browser.execute_script("sessionStorage.clear()")
        server.stop()
