"""The operator's day in the dashboard, in a real headless Chromium (issue 21): acknowledge
from the fault detail (the table marks who, unacknowledged faults stay on top), shelve (the
fault leaves the main table, "shelved only" shows it) and unshelve. Screenshots in
test-artifacts/screenshots/operator-*.png."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.http.conftest import SHOTS, needs_browser, start_server, write_config
from tests.http.test_dashboard import report, row_status, wait
from tests.http.test_operator_day import bearer, token

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.remote.webdriver import WebDriver  # noqa: E402

pytestmark = needs_browser


def table_codes(browser: WebDriver) -> list[str]:
    return [str(code) for code in browser.execute_script(
        "return [...document.querySelectorAll('#fault-table tbody tr')]"
        ".map(tr => tr.dataset.code)")]


def ack_cell(browser: WebDriver, code: str) -> str:
    return str(browser.execute_script(
        "const tr = document.querySelector(`#fault-table tr[data-code='${arguments[0]}']`);"
        "return tr ? tr.children[3].textContent : '';", code))


def test_acknowledge_and_shelve_from_the_fault_detail(browser: WebDriver, tmp_path: Path
                                                      ) -> None:
    db = tmp_path / "f.db"
    for code in ("ARM_OVERHEAT", "BASE_BUMPER", "LIDAR_DIRTY"):
        report(db, code, severity="2", description=f"{code.lower()} seen on line 3")
    tokens = tmp_path / "tokens.yaml"
    alice = token(tokens, "alice", "operator")
    server = start_server(db, config=write_config(tmp_path / "c.yaml",
                                                  http={"tokens_file": str(tokens)}))
    try:
        browser.get(server.url)
        wait(browser, lambda b: b.find_element(By.ID, "token-form").is_displayed())
        browser.find_element(By.ID, "token-input").send_keys(alice)
        browser.find_element(By.CSS_SELECTOR, "#token-form button").click()
        wait(browser, lambda b: row_status(b, "LIDAR_DIRTY") == "CONFIRMED")
        browser.find_element(By.CSS_SELECTOR, "tr[data-code='BASE_BUMPER']").click()
        wait(browser, lambda b: b.find_element(By.ID, "ack-form").is_displayed())
        assert "not yet" in browser.find_element(By.ID, "detail-fields").text
        browser.find_element(By.ID, "ack-note").send_keys("bumper taped, ticket 4711")
        browser.find_element(By.CSS_SELECTOR, "#ack-form button").click()
        wait(browser, lambda b: "alice" in ack_cell(b, "BASE_BUMPER"))
        # The acknowledged fault goes below the unacknowledged ones.
        assert table_codes(browser)[-1] == "BASE_BUMPER"
        wait(browser, lambda b: "bumper taped" in b.find_element(By.ID, "detail-fields").text)
        assert not browser.find_element(By.ID, "ack-form").is_displayed()
        browser.save_screenshot(str(SHOTS / "operator-acknowledged.png"))
        stored = server.client.get("/api/v1/faults/BASE_BUMPER", headers=bearer(alice)).json()
        assert stored["x-medkit"]["acknowledged"]["by"] == "alice"

        browser.find_element(By.CSS_SELECTOR, "tr[data-code='LIDAR_DIRTY']").click()
        wait(browser, lambda b: b.find_element(By.ID, "shelve-form").is_displayed())
        browser.find_element(By.ID, "shelve-reason").send_keys("cleaning scheduled")
        browser.find_element(By.CSS_SELECTOR, "#shelve-form button").click()
        wait(browser, lambda b: "LIDAR_DIRTY" not in table_codes(b))
        browser.find_element(By.ID, "shelved-filter").click()
        wait(browser, lambda b: table_codes(b) == ["LIDAR_DIRTY"])
        wait(browser, lambda b: b.find_element(By.ID, "unshelve-form").is_displayed())
        assert "cleaning scheduled" in browser.find_element(By.ID, "detail-fields").text
        browser.save_screenshot(str(SHOTS / "operator-shelved.png"))
        browser.find_element(By.CSS_SELECTOR, "#unshelve-form button").click()
        wait(browser, lambda b: table_codes(b) == [])
        browser.find_element(By.ID, "shelved-filter").click()
        wait(browser, lambda b: "LIDAR_DIRTY" in table_codes(b))
        history = server.client.get("/api/v1/history", params={"code": "LIDAR_DIRTY"},
                                    headers=bearer(alice)).json()["items"]
        assert [item["kind"] for item in history][-2:] == ["fault_shelved", "fault_unshelved"]
        assert history[-2]["payload"]["actor"] == "alice"
    finally:
        server.stop()
