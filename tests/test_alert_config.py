"""The config's ``alerts`` rules (docs/alerts.md, docs/configuration.md): every problem is
refused at load with one message naming the rule, and nothing starts."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from faultledger.errors import ConfigError
from faultledger.service.config import Settings, load_settings

HOOK = {"type": "webhook", "url": "http://127.0.0.1:9000/hook"}
EXAMPLE = """\
alerts:
  - name: oncall-critical
    on: [fault_confirmed, fault_cleared, fault_acknowledged, flood, stale, sync_lag]
    codes: ["HW_*", "ARM_*"]
    min_severity: ERROR
    receiver: {type: webhook, url: "http://127.0.0.1:9000/hook"}
  - name: pager
    on: [fault_confirmed, fault_acknowledged, fault_cleared]
    receiver: {type: pagerduty, url: "https://events.pagerduty.com/v2/enqueue",
               routing_key: R0UT1NGKEY}
  - name: chat
    on: [fault_confirmed]
    min_severity: 3
    sync_lag_seconds: 60
    receiver: {type: slack, url: "https://hooks.slack.com/services/T0/B0/X"}
"""


def load(tmp_path: Path, text: str) -> Settings:
    path = tmp_path / "config.yaml"
    path.write_text(text)
    return load_settings(path)


def problem(tmp_path: Path, rules: list[dict[str, Any]]) -> str:
    with pytest.raises(ConfigError) as caught:
        load(tmp_path, yaml.safe_dump({"alerts": rules}))
    message = str(caught.value)
    assert "\n" not in message
    return message.split(" is invalid: ", 1)[1]


def test_the_documented_example_loads_with_a_bare_yaml_on_key(tmp_path: Path) -> None:
    """YAML 1.1 reads ``on:`` as true; the rule takes it as ``on``."""
    rules = load(tmp_path, EXAMPLE).alerts
    assert [r.name for r in rules] == ["oncall-critical", "pager", "chat"]
    first, pager, chat = rules
    assert first.on == ["fault_confirmed", "fault_cleared", "fault_acknowledged", "flood",
                        "stale", "sync_lag"]
    assert first.codes == ["HW_*", "ARM_*"] and first.min_severity == 2
    assert first.sync_lag_seconds == 300 and first.receiver.routing_key is None
    assert pager.codes == ["*"] and pager.min_severity == 0
    assert pager.receiver.routing_key == "R0UT1NGKEY"
    assert chat.min_severity == 3 and chat.sync_lag_seconds == 60


def test_no_alerts_is_an_empty_list(tmp_path: Path) -> None:
    assert load(tmp_path, "alerts:\n").alerts == []
    assert Settings().alerts == []


@pytest.mark.parametrize(("rules", "expected"), [
    ([{"name": "a", "on": ["fault_confirmed"], "receiver": HOOK},
      {"name": "b", "on": ["fault_confirmed"], "receiver": HOOK},
      {"name": "oncall-critical", "on": ["fault_confirm"], "receiver": HOOK}],
     "alerts[2] 'oncall-critical': on: unknown event 'fault_confirm' (events: "
     "fault_confirmed, fault_updated, fault_cleared, fault_acknowledged, flood, stale, "
     "sync_lag)"),
    ([{"name": "r", "on": ["fault_shelved"], "receiver": HOOK}],
     "alerts[0] 'r': on: 'fault_shelved' is no alert event: a shelved fault alerts nothing"),
    ([{"name": "r", "on": [], "receiver": HOOK}], "alerts[0] 'r': on: List should have at "
     "least 1 item"),
    ([{"name": "r", "on": ["flood"], "codes": [""], "receiver": HOOK}],
     "alerts[0] 'r': codes: a code glob cannot be empty"),
    ([{"name": "r", "on": ["flood"], "codes": ["A" * 257], "receiver": HOOK}],
     "alerts[0] 'r': codes: a code glob is at most 256 characters, got 257"),
    ([{"name": "r", "on": ["flood"], "codes": ["HW_[AB"], "receiver": HOOK}],
     "alerts[0] 'r': codes: unbalanced '[' at position 3 in 'HW_[AB'"),
    ([{"name": "r", "on": ["stale"], "receiver": {"type": "webhook"}}],
     "alerts[0] 'r': receiver.url: Field required"),
    ([{"name": "r", "on": ["stale"], "receiver": {"type": "webhook", "url": "ftp://h/x"}}],
     "alerts[0] 'r': receiver.url: String should match pattern"),
    ([{"name": "r", "on": ["stale"], "receiver": {"type": "email", "url": "http://h/"}}],
     "alerts[0] 'r': receiver.type: Input should be 'webhook', 'slack' or 'pagerduty'"),
    ([{"name": "r", "on": ["stale"], "receiver": {"type": "pagerduty",
                                                 "url": "https://e.example/v2/enqueue"}}],
     "alerts[0] 'r': receiver: a pagerduty receiver needs routing_key"),
    ([{"name": "r", "on": ["stale"], "receiver": {**HOOK, "routing_key": "K"}}],
     "alerts[0] 'r': receiver: routing_key is for pagerduty receivers only, not webhook"),
    ([{"name": "r", "on": ["fault_updated"], "receiver": {
        "type": "pagerduty", "url": "https://e.example/v2/enqueue", "routing_key": "K"}}],
     "alerts[0] 'r': on: fault_updated has no PagerDuty event action"),
    ([{"name": "r", "on": ["stale"], "min_severity": "FATAL", "receiver": HOOK}],
     "alerts[0] 'r': min_severity: must be 0-3 or INFO/WARN/ERROR/CRITICAL, got 'FATAL'"),
    ([{"name": "r", "on": ["stale"], "min_severity": 4, "receiver": HOOK}],
     "alerts[0] 'r': min_severity: must be 0-3"),
    ([{"name": "on:call", "on": ["stale"], "receiver": HOOK}],
     "alerts[0] 'on:call': name: must be 1..64 characters"),
    ([{"on": ["stale"], "receiver": HOOK}], "alerts[0]: name: Field required"),
    ([{"name": "r", "on": ["stale"], "receiver": HOOK, "sync_lag_seconds": 0}],
     "alerts[0] 'r': sync_lag_seconds: Input should be greater than 0"),
    ([{"name": "r", "on": ["stale"], "receiver": HOOK, "colour": "red"}],
     "alerts[0] 'r': colour: Extra inputs are not permitted"),
    ([{"name": "r", "on": ["stale"], "receiver": HOOK},
      {"name": "r", "on": ["flood"], "receiver": HOOK}],
     "alerts[1] 'r': duplicate rule name (also alerts[0])"),
    (["oncall"], "alerts[0]: a rule must be a mapping, got 'oncall'"),
])
def test_each_problem_names_its_rule(tmp_path: Path, rules: list[Any], expected: str) -> None:
    assert problem(tmp_path, rules).startswith(expected)


def test_alerts_must_be_a_list(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"alerts must be a list of rules, got \{'name'"):
        load(tmp_path, "alerts: {name: x}\n")


def test_globs_fnmatch_reads_as_balanced_are_accepted(tmp_path: Path) -> None:
    rules = [{"name": "r", "on": ["stale"], "receiver": HOOK,
              "codes": ["HW_[!AB]*", "X[]]", "ARM_[LR]?", "A]B", "[!]]"]}]
    assert load(tmp_path, yaml.safe_dump({"alerts": rules})).alerts[0].codes == rules[0][
        "codes"]


def test_faultledger_http_refuses_a_bad_rule_in_one_line_and_creates_nothing(
        tmp_path: Path) -> None:
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump({"alerts": [
        {"name": "oncall", "on": ["fault_confirmed", "flod"], "receiver": HOOK}]}))
    db = tmp_path / "faults.db"
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "http", "--config",
                           str(config), "--db", str(db), "--listen", "127.0.0.1:0"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.count("\n") == 1
    assert done.stderr.startswith(f"error: config file {config} is invalid: alerts[0] "
                                  "'oncall': on: unknown event 'flod' (events: ")
    assert not db.exists()
