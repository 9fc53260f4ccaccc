"""`faultledger policy explain` and the policy's conflict warnings (issue 21, item 5): which
rule gives each debounce field of a report, and where one fault code's thresholds depend on
the reporting source (ros2_medkit issue #276: the counter is shared per code, the override is
chosen per source, so whichever report arrives decides the transition).

Real config files in tmp_path, the real CLI (typer's CliRunner, a pseudo-terminal, or a
subprocess), real SQLite ledgers."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.cells import cell_len

from faultledger import FaultLedger, FaultStatus, Policy
from faultledger.domain.fault import Fault
from faultledger.domain.policy import SourceOverride
from faultledger.domain.policy_explain import (
    DEBOUNCE_FIELDS,
    RuleKind,
    explain,
    rule_conflicts,
    source_conflicts,
)
from faultledger.service import policy_check
from faultledger.service.config import load_settings
from tests.cli_stats_scenario import assert_clean_error, invoke
from tests.test_safe_output import SGR, run_in_terminal

CLI = [sys.executable, "-m", "faultledger.cli.main"]
T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)

CONFLICTING = {"policy": {
    "confirmation_threshold": -2,
    "code_overrides": {"HW_*": {"confirmation_threshold": -3, "healing_enabled": True}},
    "overrides": {"/safety": {"confirmation_threshold": -1}},
}}
"""HW_* codes need 3 FAILED, except from under /safety: 1."""
STATIC_WARNING = ("policy: code_overrides 'HW_*' sets confirmation_threshold -3, overrides "
                  "'/safety' sets -1: a code matching 'HW_*' reported from under '/safety' "
                  "gets -1, from elsewhere -3 (the counter is shared per code; medkit #276)")


def write(tmp_path: Path, data: dict[str, Any], name: str = "faultledger.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def explained(config: Path, code: str, source: str, *args: str) -> dict[str, Any]:
    """`policy explain --json`: the answer, after checking it printed nothing on stderr."""
    result = invoke("policy", "explain", code, "--source", source, "--config", str(config),
                    "--json", *args)
    assert result.exit_code == 0, result.stderr
    assert result.stderr == ""
    data: dict[str, Any] = json.loads(result.stdout)
    return data


def origins(data: dict[str, Any]) -> dict[str, tuple[Any, str]]:
    return {name: (field["value"], field["from"]) for name, field in data["fields"].items()}


# -- which rule gives each field ---------------------------------------------------------------
def test_a_global_only_policy_gives_every_field_from_global(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {"confirmation_threshold": 4, "healing_enabled": True,
                                         "healing_threshold": -2,
                                         "auto_confirm_after_sec": 7.5}})

    data = explained(config, "MOTOR_OVERHEAT", "/motor")

    assert origins(data) == {  # sanitised as loaded: 4 -> -4, -2 -> 2
        "confirmation_threshold": (-4, "global"), "healing_enabled": (True, "global"),
        "healing_threshold": (2, "global"), "auto_confirm_after_sec": (7.5, "global")}
    assert (data["code_pattern"], data["source_prefix"], data["warnings"]) == (None, None, [])


def test_a_code_pattern_gives_the_fields_it_sets(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {"code_overrides": {
        "HW_*": {"healing_enabled": True, "healing_threshold": 0}}}})

    matching = origins(explained(config, "HW_ARM_EMERGENCY_STOP", "/arm"))
    other = origins(explained(config, "MOTOR_OVERHEAT", "/arm"))

    assert matching == {"confirmation_threshold": (-1, "global"),
                        "healing_enabled": (True, "code_overrides 'HW_*'"),
                        "healing_threshold": (0, "code_overrides 'HW_*'"),
                        "auto_confirm_after_sec": (0.0, "global")}
    assert {source for _, source in other.values()} == {"global"}


def test_a_source_prefix_gives_the_fields_it_sets_under_it_only(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {"overrides": {
        "/robot/arm": {"confirmation_threshold": -4}}}})

    under = origins(explained(config, "MOTOR_OVERHEAT", "/robot/arm/left"))
    beside = origins(explained(config, "MOTOR_OVERHEAT", "/robot/army"))

    assert under["confirmation_threshold"] == (-4, "overrides '/robot/arm'")
    assert under["healing_threshold"] == (3, "global")
    assert beside["confirmation_threshold"] == (-1, "global")  # a prefix ends at a '/'


def test_a_source_prefix_beats_a_code_pattern_field_by_field(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {
        "code_overrides": {"HW_*": {"confirmation_threshold": -3, "healing_threshold": 0}},
        "overrides": {"/robot/arm": {"confirmation_threshold": -5, "healing_enabled": True}}}})

    data = explained(config, "HW_ARM_EMERGENCY_STOP", "/robot/arm")

    assert origins(data) == {
        "confirmation_threshold": (-5, "overrides '/robot/arm'"),
        "healing_enabled": (True, "overrides '/robot/arm'"),
        "healing_threshold": (0, "code_overrides 'HW_*'"),
        "auto_confirm_after_sec": (0.0, "global")}
    assert (data["code_pattern"], data["source_prefix"]) == ("HW_*", "/robot/arm")


def test_the_most_specific_code_pattern_is_chosen(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {"code_overrides": {
        "HW_*": {"healing_threshold": 1}, "HW_ARM_*": {"healing_threshold": 2},
        "*_STOP": {"healing_threshold": 3}, "HW_ARM_?_STOP": {"healing_threshold": 4}}}})

    # longest literal part first (HW_ARM_ beats HW_ and *), then the longest pattern
    assert origins(explained(config, "HW_ARM_EMERGENCY_STOP", "/x"))["healing_threshold"] == (
        2, "code_overrides 'HW_ARM_*'")
    assert origins(explained(config, "HW_ARM_L_STOP", "/x"))["healing_threshold"] == (
        4, "code_overrides 'HW_ARM_?_STOP'")
    assert origins(explained(config, "HW_BASE_STOP", "/x"))["healing_threshold"] == (
        1, "code_overrides 'HW_*'")
    assert origins(explained(config, "LIDAR_STOP", "/x"))["healing_threshold"] == (
        3, "code_overrides '*_STOP'")


def test_the_longest_source_prefix_is_chosen(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {"overrides": {
        "/robot": {"healing_threshold": 1}, "/robot/arm": {"healing_threshold": 2},
        "/robot/arm/left": {"confirmation_threshold": -9}}}})

    left = origins(explained(config, "MOTOR_OVERHEAT", "/robot/arm/left/joint"))
    arm = origins(explained(config, "MOTOR_OVERHEAT", "/robot/arm/right"))
    base = origins(explained(config, "MOTOR_OVERHEAT", "/robot/base"))

    # the longest prefix alone applies: its unset fields are global, not a shorter prefix's
    assert left["confirmation_threshold"] == (-9, "overrides '/robot/arm/left'")
    assert left["healing_threshold"] == (3, "global")
    assert arm["healing_threshold"] == (2, "overrides '/robot/arm'")
    assert base["healing_threshold"] == (1, "overrides '/robot'")


def test_the_table_names_each_rule_and_fits_80_columns(tmp_path: Path) -> None:
    config = write(tmp_path, CONFLICTING)

    code, raw = run_in_terminal("policy", "explain", "HW_ARM_EMERGENCY_STOP", "--source",
                                "/safety/estop_monitor", "--config", str(config))
    text = SGR.sub("", raw.decode("utf-8").replace("\r\n", "\n"))

    assert code == 0, text
    assert max(cell_len(line) for line in text.splitlines()) <= 80, text
    rows = {cells[0]: cells[1:] for cells in (
        [c.strip() for c in line.split("│")[1:-1]] for line in text.splitlines()
        if line.startswith("│"))}
    assert rows == {"confirmation_threshold": ["-1", "overrides '/safety'"],
                    "healing_enabled": ["true", "code_overrides 'HW_*'"],
                    "healing_threshold": ["3", "global"],
                    "auto_confirm_after_sec": ["0.0", "global"]}
    # the warning about this code, wrapped under its label
    assert f"warning: {STATIC_WARNING}" in " ".join(text.split()), text
    assert "Traceback" not in text


@pytest.mark.parametrize(("args", "words"), [
    (("BAD CODE", "--source", "/x"), "fault_code contains invalid character ' '"),
    (("HW_A..B", "--source", "/x"), "fault_code cannot contain '..'"),
    (("", "--source", "/x"), "fault_code cannot be empty"),
    (("HW_X", "--source", ""), "source_id cannot be empty"),
    (("HW_X", "--source", "/x\x00y"), "source_id contains a NUL character"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, args: tuple[str, ...],
                                          words: str) -> None:
    config = write(tmp_path, CONFLICTING)

    result = invoke("policy", "explain", *args, "--config", str(config), "--db",
                    str(tmp_path / "missing.db"))  # the input is checked first

    assert result.exit_code == 2
    assert_clean_error(result, words)
    assert len(result.stderr.splitlines()) == 1


def test_a_bad_config_file_is_one_line_and_exit_2(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {"code_overrides": {"HW_*": {"healing": True}}}})

    result = invoke("policy", "explain", "HW_X", "--source", "/x", "--config", str(config))

    assert result.exit_code == 2
    assert_clean_error(result, "code_overrides.HW_*.healing")


def test_the_config_is_found_as_by_every_command(tmp_path: Path) -> None:
    """No --config: config/faultledger.yaml in the working directory (each test has its own)."""
    Path("config").mkdir()
    write(Path("config"), {"policy": {"healing_threshold": 6}})

    result = invoke("policy", "explain", "MOTOR_OVERHEAT", "--source", "/m", "--json")

    data = json.loads(result.stdout)
    assert data["fields"]["healing_threshold"]["value"] == 6
    assert data["config"] == "config/faultledger.yaml"


# -- the conflict warning at load ---------------------------------------------------------------
def test_explain_warns_of_a_conflict_naming_both_rules(tmp_path: Path) -> None:
    config = write(tmp_path, CONFLICTING)

    data = explained(config, "HW_ARM_EMERGENCY_STOP", "/elsewhere")
    table = invoke("policy", "explain", "HW_X", "--source", "/x", "--config", str(config))

    assert data["warnings"] == [STATIC_WARNING]
    assert table.exit_code == 0
    assert table.stderr == f"warning: {STATIC_WARNING}\n"  # piped: one whole line


def test_a_writer_given_the_config_warns_at_load_and_still_records(tmp_path: Path) -> None:
    config = write(tmp_path, CONFLICTING)
    db = str(tmp_path / "faults.db")

    result = invoke("report", "HW_ARM_EMERGENCY_STOP", "FAILED", "--source", "/safety/estop",
                    "--db", db, "--config", str(config))

    assert result.exit_code == 0, result.stderr
    assert result.stderr == f"warning: {STATIC_WARNING}\n"
    assert "HW_ARM_EMERGENCY_STOP is CONFIRMED" in result.stdout  # -1 from under /safety


@pytest.mark.parametrize("policy", [
    {},
    # two source prefixes with different values: what source overrides are for
    {"overrides": {"/a": {"confirmation_threshold": -1}, "/b": {"confirmation_threshold": -5}}},
    # a pattern and a prefix setting different fields
    {"code_overrides": {"HW_*": {"healing_enabled": True}},
     "overrides": {"/a": {"confirmation_threshold": -5}}},
    # a pattern and a prefix setting one field to the same value (5 is sanitised to -5)
    {"code_overrides": {"HW_*": {"confirmation_threshold": 5}},
     "overrides": {"/a": {"confirmation_threshold": -5}}},
], ids=["global", "two-prefixes", "other-fields", "same-value"])
def test_no_warning_without_a_conflict(tmp_path: Path, policy: dict[str, Any]) -> None:
    config = write(tmp_path, {"policy": policy})
    db = str(tmp_path / "faults.db")

    report = invoke("report", "HW_X", "FAILED", "--source", "/a/x", "--db", db,
                    "--config", str(config))
    data = explained(config, "HW_X", "/a/x")

    assert report.exit_code == 0, report.stderr
    assert report.stderr == ""
    assert (data["warnings"], data["other_warnings"]) == ([], [])
    assert rule_conflicts(load_settings(config).policy) == []


def test_each_conflicting_field_is_named_and_others_are_pointed_at(tmp_path: Path) -> None:
    config = write(tmp_path, {"policy": {
        "code_overrides": {"HW_*": {"confirmation_threshold": -3, "healing_enabled": True},
                           "NAV_*": {"healing_threshold": 0}},
        "overrides": {"/a": {"confirmation_threshold": -1, "healing_enabled": False},
                      "/b": {"healing_threshold": 2}}}})

    hw = explained(config, "HW_X", "/z")
    nav = invoke("policy", "explain", "NAV_X", "--source", "/z", "--config", str(config))

    assert [w.split(":")[1].strip() for w in hw["warnings"]] == [
        "code_overrides 'HW_*' sets confirmation_threshold -3, overrides '/a' sets -1",
        "code_overrides 'HW_*' sets healing_enabled true, overrides '/a' sets false"]
    assert hw["other_warnings"] == ["code_overrides 'NAV_*'"]
    assert nav.stderr.splitlines() == [
        "warning: policy: code_overrides 'NAV_*' sets healing_threshold 0, overrides '/b' sets "
        "2: a code matching 'NAV_*' reported from under '/b' gets 2, from elsewhere 0 (the "
        "counter is shared per code; medkit #276)",
        "note: the policy has warnings about other codes too (code_overrides 'HW_*'); explain "
        "a code they concern to see them"]


def test_a_less_specific_pattern_that_never_applies_to_the_code_is_not_its_warning(
        tmp_path: Path) -> None:
    """HW_ARM_* governs HW_ARM_X alone: HW_*'s conflict does not concern it."""
    config = write(tmp_path, {"policy": {
        "code_overrides": {"HW_*": {"confirmation_threshold": -3},
                           "HW_ARM_*": {"healing_enabled": True}},
        "overrides": {"/safety": {"confirmation_threshold": -1}}}})

    arm = explained(config, "HW_ARM_X", "/safety")
    base = explained(config, "HW_BASE_X", "/safety")

    assert (arm["warnings"], arm["other_warnings"]) == ([], ["code_overrides 'HW_*'"])
    assert len(base["warnings"]) == 1 and "'HW_*'" in base["warnings"][0]


# -- the warning from a ledger's faults ---------------------------------------------------------
def two_source_ledger(tmp_path: Path, policy: dict[str, Any]) -> str:
    """HW_ARM_EMERGENCY_STOP reported FAILED from /safety/estop and from /arm/driver, under
    ``policy``, on a real SQLite file."""
    db = f"sqlite:///{tmp_path / 'faults.db'}"
    with FaultLedger.open(db, policy=Policy.model_validate(policy), background=False) as ledger:
        for seconds, source in ((0, "/arm/driver"), (1, "/safety/estop"), (2, "/arm/driver")):
            assert ledger.report("HW_ARM_EMERGENCY_STOP", "FAILED", 2, "", source,
                                 at=T0 + timedelta(seconds=seconds)).accepted
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", at=T0).accepted
        fault = ledger.get_fault("HW_ARM_EMERGENCY_STOP")
        assert fault is not None
        assert fault.reporting_sources == ("/arm/driver", "/safety/estop")
    return db


LEDGER_WARNING = (
    "policy: HW_ARM_EMERGENCY_STOP was reported by 2 sources under different thresholds: "
    "'/arm/driver': confirmation_threshold -3 (code_overrides 'HW_*'); '/safety/estop': "
    "confirmation_threshold -1 (overrides '/safety') (whichever report arrives decides the "
    "transition; the counter is shared per code; medkit #276)")


def test_a_fault_reported_from_two_sources_under_different_overrides_is_warned_of(
        tmp_path: Path) -> None:
    db = two_source_ledger(tmp_path, CONFLICTING["policy"])
    config = write(tmp_path, CONFLICTING)

    data = explained(config, "HW_ARM_EMERGENCY_STOP", "/arm/driver", "--db", db)
    table = invoke("policy", "explain", "HW_ARM_EMERGENCY_STOP", "--source", "/arm/driver",
                   "--config", str(config), "--db", db)

    assert data["warnings"] == [STATIC_WARNING, LEDGER_WARNING]
    assert data["ledger_checked"] is True
    assert table.stderr.splitlines() == [f"warning: {STATIC_WARNING}",
                                         f"warning: {LEDGER_WARNING}"]


def test_the_ledger_warning_needs_no_static_conflict(tmp_path: Path) -> None:
    """Two source prefixes alone do not warn at load; two of them reporting one code do."""
    policy = {"overrides": {"/safety": {"confirmation_threshold": -1},
                            "/arm": {"confirmation_threshold": -3}}}
    db = two_source_ledger(tmp_path, policy)
    config = write(tmp_path, {"policy": policy})

    without = explained(config, "HW_ARM_EMERGENCY_STOP", "/arm/driver")
    with_db = explained(config, "HW_ARM_EMERGENCY_STOP", "/arm/driver", "--db", db)
    motor = explained(config, "MOTOR_OVERHEAT", "/motor", "--db", db)

    assert without["warnings"] == []
    assert with_db["warnings"] == [
        "policy: HW_ARM_EMERGENCY_STOP was reported by 2 sources under different thresholds: "
        "'/arm/driver': confirmation_threshold -3 (overrides '/arm'); '/safety/estop': "
        "confirmation_threshold -1 (overrides '/safety') (whichever report arrives decides "
        "the transition; the counter is shared per code; medkit #276)"]
    assert (motor["warnings"], motor["other_warnings"]) == ([], ["HW_ARM_EMERGENCY_STOP"])


def test_sources_that_agree_are_not_warned_of(tmp_path: Path) -> None:
    """The same two sources, under a policy that gives them the same thresholds."""
    db = two_source_ledger(tmp_path, CONFLICTING["policy"])
    config = write(tmp_path, {"policy": {"overrides": {"/safety": {"healing_threshold": 3}}}})

    data = explained(config, "HW_ARM_EMERGENCY_STOP", "/arm/driver", "--db", db)

    assert (data["warnings"], data["other_warnings"], data["ledger_checked"]) == ([], [], True)


def test_explain_db_reads_only_and_refuses_a_missing_database(tmp_path: Path) -> None:
    config = write(tmp_path, CONFLICTING)
    missing = tmp_path / "missing.db"

    result = invoke("policy", "explain", "HW_X", "--source", "/x", "--config", str(config),
                    "--db", str(missing))

    assert result.exit_code == 2
    assert result.stderr.startswith("error:") and "Traceback" not in result.stderr
    assert not missing.exists()


def test_faultledger_http_warns_at_start_from_the_policy_and_the_ledger(tmp_path: Path) -> None:
    db = two_source_ledger(tmp_path, CONFLICTING["policy"])
    config = write(tmp_path, {**CONFLICTING, "http": {"tokens_file": None}})
    log = tmp_path / "http.log"
    with log.open("w") as out:
        server = subprocess.Popen([*CLI, "http", "--db", db, "--listen", "127.0.0.1:0",
                                   "--config", str(config)], stdout=out,
                                  stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while "faultledger http ready" not in log.read_text():
            assert server.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
    finally:
        server.terminate()
        server.wait(30)
    text = log.read_text()

    assert f"warning: {STATIC_WARNING}\n" in text
    assert f"warning: {LEDGER_WARNING}\n" in text
    assert text.index(LEDGER_WARNING) < text.index("faultledger http ready")
    with FaultLedger.open(db, background=False, create=False, upgrade=False) as ledger:
        fault = ledger.get_fault("HW_ARM_EMERGENCY_STOP")
    assert fault is not None and fault.status is FaultStatus.CONFIRMED


def test_many_conflicting_faults_are_capped_in_one_more_warning() -> None:
    policy = Policy(overrides={"/a": {"confirmation_threshold": -2}})
    sources = ("/a/x", "/b")
    faults = [fault(f"CODE_{n:02}", sources) for n in range(policy_check.MAX_LEDGER_WARNINGS + 7)]

    warnings = policy_check.ledger_warnings(policy, faults)

    assert len(warnings) == policy_check.MAX_LEDGER_WARNINGS + 1
    assert warnings[0].startswith("policy: CODE_00 was reported by 2 sources")
    assert re.match(r"policy: 7 more faults were reported by sources under different "
                    r"thresholds \(CODE_20, CODE_21, CODE_22, CODE_23, CODE_24, …\)",
                    warnings[-1]), warnings[-1]


def fault(code: str, sources: tuple[str, ...]) -> Fault:
    return Fault(code, 2, "", 0, 0, 0, 1, FaultStatus.CONFIRMED, sources, -1)


# -- explain mirrors resolve ---------------------------------------------------------------------
PATTERNS = ("HW_*", "HW_ARM_*", "*_STOP", "HW_?RM_*", "MOTOR_OVERHEAT", "*", "[HM]*", "HW_A*")
PREFIXES = ("/robot", "/robot/arm", "/robot/arm/left", "/sensors", "/s", "/", "/robot/")
CODES = ("HW_ARM_STOP", "HW_BASE_STOP", "MOTOR_OVERHEAT", "LIDAR", "HW_", "X_STOP", "HW_ARM_")
SOURCES = ("/robot", "/robot/arm", "/robot/arm/left/x", "/robot/army", "/sensors/lidar", "/s",
           "/", "//x", "/x", "/robot/")

fields = st.builds(SourceOverride,
                   confirmation_threshold=st.none() | st.integers(-5, 5),
                   healing_enabled=st.none() | st.booleans(),
                   healing_threshold=st.none() | st.integers(-5, 5))
policies = st.builds(
    Policy,
    confirmation_threshold=st.integers(-5, 5),
    healing_enabled=st.booleans(),
    healing_threshold=st.integers(-5, 5),
    auto_confirm_after_sec=st.floats(0, 1e6),
    overrides=st.dictionaries(
        st.sampled_from(PREFIXES) | st.text("/ab", min_size=1, max_size=5), fields, max_size=5),
    code_overrides=st.dictionaries(
        st.sampled_from(PATTERNS) | st.text("AB_*?", min_size=1, max_size=5), fields,
        max_size=5),
)
codes = st.sampled_from(CODES) | st.text("AB_", min_size=1, max_size=6)
sources = st.sampled_from(SOURCES) | st.text("/ab", min_size=1, max_size=6)


@settings(max_examples=400, deadline=None)
@given(policies, codes, sources)
def test_explain_gives_exactly_what_resolve_gives(policy: Policy, code: str,
                                                  source: str) -> None:
    explanation = explain(policy, source, code)

    assert explanation.params == policy.resolve(source, code)
    assert explanation.field("auto_confirm_after_sec").value == policy.auto_confirm_after_sec
    for name in DEBOUNCE_FIELDS:  # each rule named really sets the value shown
        origin = explanation.field(name)
        if origin.rule.kind is RuleKind.SOURCE:
            assert origin.rule.key == explanation.prefix
            assert getattr(policy.overrides[origin.rule.key], name) == origin.value
        elif origin.rule.kind is RuleKind.CODE:
            assert origin.rule.key == explanation.pattern
            assert getattr(policy.code_overrides[origin.rule.key], name) == origin.value
            assert explanation.prefix is None or getattr(
                policy.overrides[explanation.prefix], name) is None
        else:
            assert origin.value == getattr(policy, name)


@settings(max_examples=200, deadline=None)
@given(policies, codes, st.lists(sources, min_size=1, max_size=4, unique=True))
def test_a_ledger_conflict_is_exactly_sources_that_resolve_differently(
        policy: Policy, code: str, reporters: list[str]) -> None:
    found = source_conflicts(policy, [fault(code, tuple(sorted(reporters)))])

    differ = len({policy.resolve(source, code) for source in reporters}) > 1
    assert bool(found) == differ
    if found:
        assert sorted(s for group in found[0].groups for s in group.sources) == sorted(reporters)


@settings(max_examples=200, deadline=None)
@given(policies)
def test_without_a_static_conflict_a_code_pattern_field_holds_for_every_source_setting_it(
        policy: Policy) -> None:
    """No conflict: a source prefix that sets a field the chosen pattern sets agrees with it."""
    if rule_conflicts(policy):
        return
    for code in CODES:
        for source in SOURCES:
            explanation = explain(policy, source, code)
            if explanation.pattern is None:
                continue
            pattern = policy.code_overrides[explanation.pattern]
            for name in DEBOUNCE_FIELDS:
                if getattr(pattern, name) is not None:
                    assert explanation.field(name).value == getattr(pattern, name)
