"""A real fleet central and real robot logs for the store-and-forward tests (docs/fleet.md).

``Central.start(...)`` runs `faultledger http --db URL` in a subprocess on a loopback port (a
SQLite file or a PostgreSQL database) with a token file of its own; ``robot_token`` makes a
token with `faultledger token create` and writes it to a file as a robot would keep it.
``robot_log`` writes a log through the FaultLedger API; ``robot_hashes`` reads a log's
(seq, hash) pairs with sqlite3 (not through faultledger); ``sync`` runs `faultledger sync`.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import yaml

from faultledger import FaultLedger, Policy, ReportRequest

CLI = [sys.executable, "-m", "faultledger.cli.main"]
READY = re.compile(r"faultledger http ready.*?: (http://[0-9.:\[\]]+/)")


def run_cli(*args: str, timeout: float = 120, cwd: Path | None = None
            ) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout,
                          check=False, cwd=cwd, stdin=subprocess.DEVNULL)


@dataclass
class Central:
    """`faultledger http` as a fleet central; ``admin`` is a token that reads everything."""

    url: str
    db: str
    directory: Path
    tokens: Path
    listen: str
    admin: str = ""
    process: subprocess.Popen[str] | None = None
    log: Path | None = None
    extra: list[str] = field(default_factory=list)

    @classmethod
    def start(cls, directory: Path, db: str, listen: str = "127.0.0.1:0") -> Central:
        directory.mkdir(parents=True, exist_ok=True)
        tokens = directory / "central-tokens.yaml"
        central = cls("", db, directory, tokens, listen)
        central.admin = central.token("supervisor", "admin")
        central.run()
        return central

    def token(self, name: str, role: str) -> str:
        """A token made on the central with `faultledger token create`. A running central
        reads its token file again every second ("accepts it within 2 s", says the
        command): the token is returned once the central accepts it, as a script would
        wait, so that a client started at once is not refused."""
        done = run_cli("token", "create", "--name", name, "--role", role, "--file",
                       str(self.tokens))
        assert done.returncode == 0, done.stderr
        token = done.stdout.strip()
        if self.process is not None and self.process.poll() is None:
            deadline = time.monotonic() + 10
            with httpx.Client(base_url=self.url, timeout=5,
                              headers={"authorization": f"Bearer {token}"}) as web:
                while web.get("/api/v1/fleet/robots").status_code == 401:
                    assert time.monotonic() < deadline, f"token {name} not accepted in 10 s"
                    time.sleep(0.05)
        return token

    def run(self) -> None:
        """Start (again, on the same port once it is known)."""
        config = self.directory / "central.yaml"
        config.write_text(yaml.safe_dump({"http": {"tokens_file": str(self.tokens)}}))
        self.log = self.directory / f"central-{time.monotonic_ns()}.log"
        with self.log.open("w") as out:
            self.process = subprocess.Popen(
                [*CLI, "http", "--db", self.db, "--listen", self.listen, "--config",
                 str(config)], stdout=out, stderr=subprocess.STDOUT, text=True,
                stdin=subprocess.DEVNULL, cwd=self.directory)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            found = READY.search(self.log.read_text())
            if found:
                self.url = found.group(1)
                self.listen = self.url.removeprefix("http://").rstrip("/")
                return
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        self.stop(signal.SIGKILL)
        raise AssertionError("the central did not start:\n" + self.log.read_text())

    def stop(self, sig: int = signal.SIGTERM) -> int | None:
        if self.process is None:
            return None
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(15)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, timeout=30,
                            headers={"authorization": f"Bearer {self.admin}"})

    def hashes(self, ledger_id: str) -> list[tuple[int, str]]:
        """Every (seq, hash) the central holds of one log, paged as verify --central does."""
        found: list[tuple[int, str]] = []
        with self.client() as web:
            while True:
                answer = web.get("/api/v1/fleet/records", params={
                    "ledger_id": ledger_id, "after_seq": found[-1][0] if found else 0})
                if answer.status_code == 404:
                    return found
                assert answer.status_code == 200, answer.text
                page = [(int(i["seq"]), str(i["hash"])) for i in answer.json()["items"]]
                if not page:
                    return found
                found += page

    def robots(self) -> list[dict[str, Any]]:
        with self.client() as web:
            answer = web.get("/api/v1/fleet/robots")
            assert answer.status_code == 200, answer.text
            items: list[dict[str, Any]] = answer.json()["items"]
            return items

    def last_seq(self, ledger_id: str) -> int:
        return max((int(r["last_seq"]) for r in self.robots() if r["ledger_id"] == ledger_id),
                   default=0)


def robot_token(central: Central, robot_id: str, path: Path) -> Path:
    """A robot's token made on the central, kept in ``path`` the way `token create`'s
    output is redirected (``faultledger token create … > robot.token``)."""
    path.write_text(central.token(robot_id, "robot") + "\n")
    path.chmod(0o600)
    return path


def robot_log(path: Path, records: int, robot_id: str = "robot-a") -> tuple[str, str]:
    """A robot's log of about ``records`` records (its identity and policy, then reports in
    bursts of 500); returns (robot_id, ledger_id)."""
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy(), robot_id=robot_id) as ledger:
        add_reports(ledger, records - ledger.last_seq)
        identity = ledger.identity
    assert identity is not None
    return identity.robot_id, identity.ledger_id


def add_reports(ledger: FaultLedger, count: int, prefix: str = "CODE") -> None:
    done = 0
    while done < count:
        size = min(500, count - done)
        results = ledger.report_many([
            ReportRequest(f"{prefix}_{(done + i) % 40:02d}", "FAILED" if (done + i) % 3
                          else "PASSED", 2, f"report {done + i}", f"/robot/{(done + i) % 7}")
            for i in range(size)])
        assert all(r.accepted for r in results)
        done += size


def robot_hashes(path: Path) -> list[tuple[int, str]]:
    """The robot log's (seq, hash) pairs, read with sqlite3."""
    with contextlib.closing(sqlite3.connect(path)) as conn:
        return [(int(seq), str(digest)) for seq, digest in
                conn.execute("SELECT seq, hash FROM events ORDER BY seq")]


def sync(db: Path, central: Central, token: Path, *extra: str, timeout: float = 120,
         url: str | None = None) -> subprocess.CompletedProcess[str]:
    return run_cli("sync", "--db", str(db), "--central", url or central.url, "--token-file",
                   str(token), *extra, timeout=timeout)


def start_sync(db: Path, url: str, token: Path, log: Path, *extra: str
               ) -> subprocess.Popen[str]:
    """`faultledger sync` in the background, its output in ``log``."""
    with log.open("w") as out:
        return subprocess.Popen([*CLI, "sync", "--db", str(db), "--central", url,
                                 "--token-file", str(token), *extra],
                                stdout=out, stderr=subprocess.STDOUT, text=True,
                                stdin=subprocess.DEVNULL, env={**os.environ})


def wait_for(condition: Any, timeout: float, interval: float = 0.05) -> bool:
    """Poll ``condition()`` until it is true or ``timeout`` passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(interval)
    return bool(condition())
