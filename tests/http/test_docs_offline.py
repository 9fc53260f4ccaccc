"""/docs works on a robot without internet: Swagger UI comes from the server's own assets
(fastapi-offline), never from a CDN; ReDoc, whose page fetches Redocly's logo from its CDN
however its script is served, is off. A real `faultledger http` and a real headless Chromium;
the machine has no network, and the tests also check that nothing the page loads or references
is anywhere but the server itself."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from urllib.parse import urlsplit

from tests.http.conftest import SHOTS, Server, needs_browser, write_config

URL = re.compile(r"""https?://[^\s"'<>)]+""", re.IGNORECASE)
SCHEMELESS = re.compile(r"""(?:(?:src|href|action)\s*=\s*["']?|url\(\s*["']?)(//[^\s"'<>)]+)""",
                        re.IGNORECASE)
"""``//host/x`` in an attribute or a style sheet: another host, over the page's scheme."""
HTML_PAGES = ("/", "/docs", "/docs/oauth2-redirect", "/api/v1/shift-report")
"""Every HTML page the server serves."""


def foreign(urls: list[str], server: Server) -> list[str]:
    """The URLs that are not the server's own (protocol-relative ones count as foreign)."""
    own = urlsplit(server.url).netloc
    return [u for u in urls if urlsplit(u if "//" in u else "//x").netloc not in ("", own)]


def test_no_served_html_references_another_host(http_server: Callable[..., Server]) -> None:
    server = http_server()
    answer = server.client.post("/api/v1/reports", json={"fault_code": "DOCS_X",
                                                         "event_type": "FAILED", "severity": 3})
    assert answer.status_code == 200
    for path in HTML_PAGES:
        page = server.client.get(path)
        assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
        found = URL.findall(page.text) + SCHEMELESS.findall(page.text)
        assert foreign(found, server) == [], (path, found)
    docs = server.client.get("/docs").text
    for asset in re.findall(r'(?:src|href)="(/static-offline-docs/[^"]+)"', docs):
        assert server.client.get(asset).status_code == 200, asset
    assert len(re.findall(r'(?:src|href)="/static-offline-docs/', docs)) == 3  # js, css, icon
    redoc = server.client.get("/redoc")
    assert redoc.status_code == 404 and redoc.json()["reason"] == "not_found"


@needs_browser
def test_swagger_ui_renders_the_api_offline(browser: object,
                                            http_server: Callable[..., Server]) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.remote.webdriver import WebDriver
    from selenium.webdriver.support.ui import WebDriverWait

    assert isinstance(browser, WebDriver)
    server = http_server()
    browser.get(server.url + "docs")
    selector = ".opblock-get .opblock-summary-path[data-path='/api/v1/faults']"
    WebDriverWait(browser, 15, poll_frequency=0.05).until(
        lambda b: b.find_elements(By.CSS_SELECTOR, selector))
    operation = browser.find_element(By.CSS_SELECTOR, selector)
    assert operation.is_displayed() and operation.text.replace("\u200b", "") == "/api/v1/faults"
    paths = {e.get_attribute("data-path") for e in browser.find_elements(
        By.CSS_SELECTOR, ".opblock-summary-path")}
    assert {"/api/v1/faults/{fault_code}", "/api/v1/apps/{app_id}/faults/{fault_code}",
            "/api/v1/reports", "/api/v1/history", "/metrics"} <= paths
    deletes = browser.find_elements(
        By.CSS_SELECTOR, ".opblock-delete .opblock-summary-path[data-path="
        "'/api/v1/components/{component_id}/faults']")
    assert len(deletes) == 1
    assert browser.find_elements(By.CSS_SELECTOR, ".errors-wrapper") == []  # spec rendered
    loaded = browser.execute_script(
        "return performance.getEntriesByType('resource').map(e => e.name)"
        ".concat(performance.getEntriesByType('navigation').map(e => e.name))")
    assert any(u.endswith("/static-offline-docs/swagger-ui-bundle.js") for u in loaded)
    assert any(u.endswith("/openapi.json") for u in loaded)
    assert foreign(loaded, server) == [], loaded
    referenced = browser.execute_script(
        "return [...document.querySelectorAll('[src],[href],[action]')]"
        ".map(e => e.getAttribute('src') || e.getAttribute('href') || e.getAttribute('action'))"
        ".map(u => new URL(u, document.baseURI).href)")
    assert foreign([u for u in referenced if u.startswith(("http:", "https:"))],
                   server) == [], referenced
    browser.save_screenshot(str(SHOTS / "api-docs-offline.png"))


def test_docs_need_a_token_once_tokens_exist(tmp_path: Path,
                                            http_server: Callable[..., Server]) -> None:
    """The API's description needs a reader's token as the API does (issue 18); Swagger UI's
    own script describes nothing and loads without (tests/http/test_tokens.py has more)."""
    config = write_config(tmp_path / "c.yaml", http={
        "tokens": [{"name": "a", "role": "viewer", "sha256": "0" * 64}]})
    server = http_server(config=config)
    for path in ("/docs", "/openapi.json"):
        assert server.client.get(path).status_code == 401, path
    assert server.client.get("/static-offline-docs/swagger-ui-bundle.js").status_code == 200
    assert server.client.get("/api/v1/faults").status_code == 401
