"""The test suite passes in a checkout a user has worked in: after `make run` (a database in
var/), the README's `token create` (var/http-tokens.yaml, which locks the API to tokens) and
`demo`, the tests that once read those files still pass, and the user's files are untouched.

This runs in a copy of the tree, exactly as a user leaves it, then runs tests of that copy
(the ones that broke: the HTTP API and the no-token loopback rule) with pytest there.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "faultledger.cli.main"]
SELECTED = ["tests/http/test_auth_and_stream.py::test_no_tokens_means_loopback_only",
            "tests/http/test_auth_and_stream.py::test_roles_decide_what_a_token_may_do",
            "tests/http/test_api.py", "tests/test_cli_usability.py::test_version"]


def tracked_files() -> list[str]:
    done = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                          check=False, timeout=60)
    if done.returncode != 0:
        pytest.skip("not a git checkout")
    return [name for name in done.stdout.decode().split("\0") if name]


def digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def run(checkout: Path, *args: str, timeout: float = 120) -> str:
    """The CLI in the checkout; the demo's scratch database lands beside the checkout."""
    env = {**os.environ, "TMPDIR": str(checkout.parent)}
    done = subprocess.run([*CLI, *args], cwd=checkout, capture_output=True, text=True,
                          timeout=timeout, check=False, stdin=subprocess.DEVNULL, env=env)
    assert done.returncode == 0, f"{args}: {done.stdout}{done.stderr}"
    return done.stdout


def test_the_suite_passes_after_run_token_create_and_demo(tmp_path: Path) -> None:
    checkout = tmp_path / "checkout"
    for name in tracked_files():
        target = checkout / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, target)
    # What `make run` and the README leave behind: the server's database (written as the
    # server does, through the shipped config), a token, and the demo.
    run(checkout, "report", "DEMO_WHEEL_SLIP", "FAILED", "--severity", "ERROR",
        "--source", "/demo")
    token = run(checkout, "token", "create", "--name", "alice", "--role", "operator")
    assert "flt_" in token
    assert (checkout / "var" / "http-tokens.yaml").is_file()
    assert (checkout / "var" / "faultledger.db").is_file()
    run(checkout, "demo")
    before = digest(checkout / "var")

    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *SELECTED],
        cwd=checkout, capture_output=True, text=True, timeout=600, check=False,
        stdin=subprocess.DEVNULL)

    tail = "\n".join(done.stdout.splitlines()[-30:])
    assert done.returncode == 0, tail + done.stderr[-2000:]
    assert " passed" in tail and "failed" not in tail and "error" not in tail.lower()
    assert digest(checkout / "var") == before, "the tests changed the user's var/"
