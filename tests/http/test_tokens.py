"""Tokens as an operator handles them, with real processes (issue 18): concurrent `token create`
runs lose nothing, a running server follows the token file (revoked: refused, new: accepted,
broken: the tokens in force kept), expiry, `token list` at 80 columns and as JSON, refused
names and roles in one line (exit 2), and the API's description behind a reader's token."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
import yaml

from faultledger.errors import Reason
from faultledger.http.auth import Authorizer
from faultledger.http.errors import ApiError
from faultledger.service.config import TokenEntry
from faultledger.service.tokens import TokenBook, digest
from tests.http.conftest import Server, write_config

CLI = [sys.executable, "-m", "faultledger.cli.main"]
FAULTS = "/api/v1/faults"
PICKUP_LIMIT_SEC = 5.0


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60,
                          env={**os.environ, **(env or {})})


def create(file: Path, name: str, role: str, *extra: str) -> str:
    done = run("token", "create", "--name", name, "--role", role, "--file", str(file), *extra)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def served(http_server: Callable[..., Server], tmp_path: Path, tokens: Path) -> Server:
    config = write_config(tmp_path / "config.yaml", http={"tokens_file": str(tokens)})
    return http_server(config=config)


def wait_for(server: Server, token: str, status: int) -> float:
    """Seconds until ``GET /api/v1/faults`` with ``token`` answers ``status``."""
    started = time.monotonic()
    while True:
        answer = server.client.get(FAULTS, headers=bearer(token))
        if answer.status_code == status:
            return time.monotonic() - started
        assert time.monotonic() - started < PICKUP_LIMIT_SEC, (
            f"still {answer.status_code} after {PICKUP_LIMIT_SEC} s: {answer.text}")
        time.sleep(0.05)


def test_twenty_concurrent_creates_keep_every_token(http_server: Callable[..., Server],
                                                    tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    runs = [subprocess.Popen([*CLI, "token", "create", "--name", f"robot-{i}", "--role",
                              "viewer", "--file", str(tokens)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for i in range(20)]
    printed = []
    for process in runs:
        out, err = process.communicate(timeout=120)
        assert process.returncode == 0, err
        printed.append(out.strip())
    stored = yaml.safe_load(tokens.read_text())["tokens"]
    assert sorted(entry["name"] for entry in stored) == sorted(f"robot-{i}" for i in range(20))
    assert {entry["sha256"] for entry in stored} == {digest(token) for token in printed}
    assert stat.S_IMODE(tokens.stat().st_mode) == 0o600
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    server = served(http_server, tmp_path, tokens)
    assert "tokens: 20" in server.output()
    for token in printed:
        assert server.client.get(FAULTS, headers=bearer(token)).status_code == 200


def test_a_running_server_follows_the_token_file(http_server: Callable[..., Server],
                                                 tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    admin = create(tokens, "root", "admin")
    viewer = create(tokens, "wall-display", "viewer")
    server = served(http_server, tmp_path, tokens)
    assert server.client.get(FAULTS, headers=bearer(viewer)).status_code == 200

    done = run("token", "revoke", "wall-display", "--file", str(tokens))
    assert done.returncode == 0, done.stderr
    assert "revoked" in done.stdout and "within 2 s" in done.stdout
    refused_after = wait_for(server, viewer, 401)
    refused = server.client.get(FAULTS, headers=bearer(viewer))
    assert refused.json()["message"] == "unknown or revoked token"

    started = time.monotonic()
    late = create(tokens, "late-comer", "operator")
    accepted_after = wait_for(server, late, 200) + (time.monotonic() - started)
    assert server.client.get(FAULTS, headers=bearer(admin)).status_code == 200
    print(f"revoked token refused after {refused_after:.2f} s; new token accepted "
          f"{accepted_after:.2f} s after `token create` started")

    # A broken file keeps the tokens in force, and says so once.
    tokens.write_text("tokens: [{name: 'bad name', role: nobody}]\n")
    time.sleep(2.5)
    assert server.client.get(FAULTS, headers=bearer(late)).status_code == 200
    assert server.client.get(FAULTS).status_code == 401
    complaints = [line for line in server.output().splitlines()
                  if "token file changed but cannot be used" in line]
    assert len(complaints) == 1, server.output()
    assert "keeping the tokens in force" in complaints[0]
    # Removing the file takes its tokens away: none left, a loopback server is open again.
    tokens.unlink()
    started = time.monotonic()
    while server.client.get(FAULTS).status_code != 200:
        assert time.monotonic() - started < PICKUP_LIMIT_SEC
        time.sleep(0.05)


def test_a_server_without_tokens_needs_one_once_a_token_is_created(
        http_server: Callable[..., Server], tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    server = served(http_server, tmp_path, tokens)
    assert "no tokens: loopback only" in server.output()
    assert server.client.get(FAULTS).status_code == 200
    token = create(tokens, "first", "viewer")
    started = time.monotonic()
    while server.client.get(FAULTS).status_code != 401:
        assert time.monotonic() - started < PICKUP_LIMIT_SEC
        time.sleep(0.05)
    assert server.client.get(FAULTS, headers=bearer(token)).status_code == 200


def test_expired_tokens_are_refused_with_when(http_server: Callable[..., Server],
                                              tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    before = datetime.now(UTC)
    short = create(tokens, "short", "viewer", "--expires", "2s")
    after = datetime.now(UTC)
    month = create(tokens, "month", "viewer", "--expires", "30d")
    stored = {entry["name"]: entry for entry in yaml.safe_load(tokens.read_text())["tokens"]}
    expires = datetime.fromisoformat(stored["short"]["expires_at"])
    assert before + timedelta(seconds=2) <= expires <= after + timedelta(seconds=3)
    in_a_month = datetime.fromisoformat(stored["month"]["expires_at"]) - after
    assert timedelta(days=30) <= in_a_month <= timedelta(days=30, minutes=1)
    # An entry written by hand, with a past time and no zone (read as UTC).
    written = yaml.safe_load(tokens.read_text())
    written["tokens"].append({"name": "old", "role": "admin", "sha256": digest("flt_old"),
                              "expires_at": "2024-03-01 08:00:00"})
    tokens.write_text(yaml.safe_dump(written))
    server = served(http_server, tmp_path, tokens)
    assert server.client.get(FAULTS, headers=bearer(month)).status_code == 200
    old = server.client.get(FAULTS, headers=bearer("flt_old"))
    assert old.status_code == 401 and old.json()["reason"] == "unauthorized"
    assert old.json()["message"].startswith(
        "token 'old' expired at 2024-03-01 08:00:00 UTC")
    assert 'error="invalid_token"' in old.headers["WWW-Authenticate"]
    time.sleep(max(0.0, (expires - datetime.now(UTC)).total_seconds()) + 0.1)
    refused = server.client.get(FAULTS, headers=bearer(short))
    assert refused.status_code == 401
    assert refused.json()["message"].startswith(
        f"token 'short' expired at {expires:%Y-%m-%d %H:%M:%S} UTC")
    listed = {row["name"]: row for row in json.loads(
        run("token", "list", "--file", str(tokens), "--json").stdout)}
    assert listed["short"]["expired"] and listed["old"]["expired"]
    assert not listed["month"]["expired"]


def test_token_list_fits_80_columns_and_shows_no_secret(tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    long_name = "robot-12.line-3@plant-berlin-east-hall-7.example"
    issued = [create(tokens, "alice", "operator", "--expires", "12h"),
              create(tokens, long_name, "viewer"),
              create(tokens, "gone", "reporter", "--expires", "1s")]
    time.sleep(1.2)
    config = write_config(tmp_path / "config.yaml", http={
        "tokens_file": str(tokens),
        "tokens": [{"name": "inline", "role": "admin", "sha256": digest("flt_inline")}]})
    done = run("token", "list", "--config", str(config), env={"COLUMNS": "80"})
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    print(done.stdout)
    assert all(len(line) <= 80 for line in lines)
    assert lines[0].split() == ["NAME", "ROLE", "EXPIRES", "(UTC)", "CREATED", "(UTC)"]
    assert long_name in lines  # whole, on a line of its own
    text = done.stdout
    assert "operator" in text and "never" in text and "(expired)" in text
    assert "admin*" in text and text.rstrip().endswith(
        "* in the config's http.tokens: edit the config to remove it")
    secrets = [*issued, *(digest(token) for token in issued), digest("flt_inline")]
    assert not [secret for secret in secrets if secret in text]

    rows = json.loads(run("token", "list", "--config", str(config), "--json").stdout)
    assert [row["name"] for row in rows] == ["alice", long_name, "gone", "inline"]
    assert set(rows[0]) == {"name", "role", "expires_at", "expired", "created_at", "source"}
    assert rows[1]["expires_at"] is None and rows[3]["source"] == "config"
    assert rows[0]["expires_at"].endswith("Z") and rows[0]["created_at"].endswith("Z")
    assert not [secret for secret in secrets if secret in json.dumps(rows)]

    empty = run("token", "list", "--file", str(tmp_path / "none.yaml"))
    assert empty.returncode == 0 and empty.stdout.startswith("no tokens")
    assert json.loads(run("token", "list", "--file", str(tmp_path / "none.yaml"),
                          "--json").stdout) == []


@pytest.mark.parametrize("name", ["a b", "", "x" * 65, "émile", "a/b", "-"])
def test_invalid_names_exit_2_with_the_rule(tmp_path: Path, name: str) -> None:
    tokens = tmp_path / "tokens.yaml"
    done = run("token", "create", "--name", name, "--role", "viewer", "--file", str(tokens))
    if name == "-":  # a valid name: one of the allowed characters
        assert done.returncode == 0, done.stderr
        return
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1, done.stderr
    assert f"invalid token name {name!r}" in done.stderr
    assert "1..64 characters: letters, digits, _ . @ -" in done.stderr
    assert "Traceback" not in done.stderr and not tokens.exists()


def test_refusals_of_token_commands(tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    for args, code, says in [
        (["create", "--name", "x", "--role", "root"], 2,
         "invalid role 'root': a role is one of viewer, reporter, operator, admin"),
        (["create", "--name", "x", "--role", "viewer", "--expires", "30"], 2,
         "invalid expiry '30': give a positive whole number and a unit s, m, h or d"),
        (["create", "--name", "x", "--role", "viewer", "--expires", "0s"], 2,
         "invalid expiry '0s'"),
        (["create", "--name", "x", "--role", "viewer", "--expires", "99999999d"], 2,
         "at most 36500d"),
        (["revoke", "a b"], 2, "invalid token name 'a b'"),
    ]:
        done = run("token", *args, "--file", str(tokens))
        assert done.returncode == code, (args, done.stderr)
        assert says in done.stderr and done.stderr.count("\n") == 1, done.stderr
    assert not tokens.exists()
    create(tokens, "alice", "viewer")
    missing = run("token", "revoke", "bob", "--file", str(tokens))
    assert missing.returncode == 1
    assert missing.stderr == f"error: no token named 'bob' in {tokens} (its tokens: alice)\n"
    twice = run("token", "create", "--name", "alice", "--role", "viewer", "--file", str(tokens))
    assert twice.returncode == 2 and "a token named 'alice' exists" in twice.stderr
    config = write_config(tmp_path / "config.yaml", http={
        "tokens_file": str(tokens),
        "tokens": [{"name": "inline", "role": "admin", "sha256": digest("flt_inline")}]})
    inline = run("token", "revoke", "inline", "--config", str(config))
    assert inline.returncode == 1 and "in the config's http.tokens" in inline.stderr
    assert run("token", "revoke", "alice", "--file", str(tokens)).returncode == 0
    assert yaml.safe_load(tokens.read_text())["tokens"] == []


def test_the_api_description_needs_a_readers_token(http_server: Callable[..., Server],
                                                   tmp_path: Path) -> None:
    tokens = tmp_path / "tokens.yaml"
    viewer, reporter = create(tokens, "wall", "viewer"), create(tokens, "plc", "reporter")
    server = served(http_server, tmp_path, tokens)
    client = server.client
    for path in ("/openapi.json", "/docs"):
        refused = client.get(path)
        assert refused.status_code == 401, path
        assert refused.json()["reason"] == "unauthorized"
        assert refused.headers["WWW-Authenticate"].startswith("Bearer")
        assert client.get(path, headers=bearer("flt_wrong")).status_code == 401
        assert client.get(path, headers=bearer(reporter)).status_code == 403
        assert client.get(path, headers=bearer(viewer)).status_code == 200
    spec = client.get("/openapi.json", headers=bearer(viewer)).json()
    assert spec["components"]["securitySchemes"]["bearer"] == {
        "type": "http", "scheme": "bearer",
        "description": spec["components"]["securitySchemes"]["bearer"]["description"]}
    assert spec["paths"]["/api/v1/faults"]["get"]["security"] == [{"bearer": []}]
    assert "security" not in spec["paths"].get("/health", {}).get("get", {})
    # Swagger UI's own script and style describe nothing of the API: they stay open.
    assert client.get("/static-offline-docs/swagger-ui.css").status_code == 200
    assert client.get("/health").status_code == 200


def test_without_tokens_the_api_description_stays_open(http_server: Callable[..., Server],
                                                       tmp_path: Path) -> None:
    server = served(http_server, tmp_path, tmp_path / "none.yaml")
    assert server.client.get("/openapi.json").status_code == 200
    assert server.client.get("/docs").status_code == 200


def test_a_server_beyond_loopback_never_falls_open() -> None:
    """Revoking every token of a server listening on 0.0.0.0 leaves it closed (in-process:
    tests never listen beyond loopback)."""
    entry = TokenEntry(name="a", role="viewer", sha256=digest("flt_a"))
    exposed = Authorizer(TokenBook([entry]), open_without_tokens=False)
    assert exposed.principal("Bearer flt_a").name == "a"
    exposed.replace(TokenBook([]))
    with pytest.raises(ApiError) as refused:
        exposed.principal("Bearer flt_a")
    assert refused.value.reason == Reason.UNAUTHORIZED
    assert "no tokens left" in refused.value.message
    loopback = Authorizer(TokenBook([]), open_without_tokens=True)
    assert loopback.principal(None).name == "anonymous"
