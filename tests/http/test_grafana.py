"""The Grafana dashboard and the Prometheus alerting rules in docs/grafana/ query only what
``/metrics`` really exposes (docs/grafana/README.md).

A real `faultledger http` gets faults of every severity reported through the API and a robot's
log pushed to it (so it is a fleet central and the ``faultledger_fleet_*`` series exist); then
every panel's and every rule's PromQL is parsed and each series name, label name and label
value it selects is looked up in that scrape (tests/http/promql_check.py). The check's own tests
show that it fails on a wrong name, label, value or variable.
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import promql_parser
import pytest
import yaml

from tests.http.conftest import Server, start_server, write_config
from tests.http.promql_check import (
    ANNOTATION_LABEL,
    TEMPLATE_LABEL,
    Scrape,
    labels_of,
    metric_names,
    panels,
    problems,
    substitute,
    variable_query_problems,
)
from tests.http.test_fleet_api import PUSH, body
from tests.test_fleet_central import records_of, robot_log

DOCS = Path(__file__).resolve().parents[2] / "docs" / "grafana"
DASHBOARD = DOCS / "faultledger.json"
RULES = DOCS / "faultledger-alerts.rules.yml"
SEVERITIES = ("INFO", "WARN", "ERROR", "CRITICAL")
PANEL_TYPES = {"row", "stat", "timeseries", "table"}
DATASOURCE = {"type": "prometheus", "uid": "${datasource}"}
RULE_KEYS = {"alert", "expr", "for", "keep_firing_for", "labels", "annotations"}
ROBOT = "robot-grafana"


def dashboard() -> dict[str, Any]:
    found: dict[str, Any] = json.loads(DASHBOARD.read_text(encoding="utf-8"))
    return found


def rules() -> list[dict[str, Any]]:
    document = yaml.safe_load(RULES.read_text(encoding="utf-8"))
    return [rule for group in document["groups"] for rule in group["rules"]]


def stand_ins(board: dict[str, Any]) -> dict[str, str]:
    """A value per template variable, as Grafana would put it into a query: a query
    variable's "All" value (a regex), a data source variable's name."""
    found = {}
    for variable in board["templating"]["list"]:
        found[variable["name"]] = variable.get("allValue") or variable["name"]
    return found


def targets(board: dict[str, Any]) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    for panel in panels(board["panels"]):
        for target in panel.get("targets", []):
            yield panel, target


@pytest.fixture(scope="module")
def central(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """Faults of every severity confirmed (one FAILED confirms by default) plus a PASSED, and
    a robot's log pushed: the labelled series all have data."""
    folder = tmp_path_factory.mktemp("grafana")
    # An alert rule, so the faultledger_alert_* series exist: its receiver is a closed
    # loopback port (nothing listens), so its deliveries are retrying.
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()
    rule = {"name": "grafana", "on": ["fault_confirmed"],
            "receiver": {"type": "webhook", "url": f"http://127.0.0.1:{port}/hook"}}
    server = start_server(folder / "central.db", config=write_config(
        folder / "config.yaml", extra={"alerts": [rule]}))
    try:
        for severity, label in enumerate(SEVERITIES):
            answer = server.client.post("/api/v1/reports", json={
                "fault_code": f"GRAFANA_{label}", "event_type": "FAILED",
                "severity": severity, "source_id": "/grafana/test"})
            assert answer.status_code == 200 and answer.json()["accepted"], answer.text
        answer = server.client.post("/api/v1/reports", json={
            "fault_code": "GRAFANA_OK", "event_type": "PASSED", "severity": 1})
        assert answer.status_code == 200 and answer.json()["accepted"], answer.text
        robot_id, ledger_id, records = records_of(robot_log(folder / "robot.db", ROBOT, 12))
        answer = server.client.post(PUSH, json=body(robot_id, ledger_id, records,
                                                    records[-1].seq))
        assert answer.status_code == 200, answer.text
    except BaseException:
        server.stop()
        raise
    yield server
    server.stop()


@pytest.fixture(scope="module")
def scrape(central: Server) -> Scrape:
    answer = central.client.get("/metrics")
    assert answer.status_code == 200, answer.text
    found = Scrape.parse(answer.text)
    for label in SEVERITIES:
        assert found.value("faultledger_faults", status="CONFIRMED", severity=label) == 1
    assert found.value("faultledger_reports_total", event_type="PASSED") == 1
    assert found.series["faultledger_records_total"]["kind"]
    assert found.series["faultledger_fleet_lag_seconds"]["robot_id"] == {ROBOT}
    assert found.series["faultledger_alert_deliveries"]["state"] == {
        "pending", "retrying", "delivered", "failed"}
    return found


# -- the dashboard ---------------------------------------------------------------------------


def test_dashboard_is_a_grafana_dashboard_on_a_datasource_variable() -> None:
    board = dashboard()
    assert board["schemaVersion"] >= 36 and board["uid"] and board["title"]
    variables = {v["name"]: v for v in board["templating"]["list"]}
    assert variables["datasource"]["type"] == "datasource"
    assert variables["datasource"]["query"] == "prometheus"
    everything = list(panels(board["panels"]))
    assert any(panel.get("targets") for panel in everything), "the dashboard has no panel"
    ids = [panel["id"] for panel in everything]
    assert len(ids) == len(set(ids)), "panel ids repeat"
    nested = [p for row in board["panels"] if row["type"] == "row" for p in row["panels"]]
    assert nested and all(p in everything for p in nested), "rows' panels are not walked"
    for panel in everything:
        assert panel["type"] in PANEL_TYPES, panel["title"]
        assert {"x", "y", "w", "h"} <= set(panel["gridPos"]), panel["title"]
        if panel["type"] == "row":
            continue
        assert panel.get("targets"), f"{panel['title']}: no query"
        assert panel.get("datasource") == DATASOURCE, panel["title"]
        refs = [target["refId"] for target in panel["targets"]]
        assert len(refs) == len(set(refs)), panel["title"]
        for target in panel["targets"]:
            assert target.get("datasource", DATASOURCE) == DATASOURCE, panel["title"]
            assert target["expr"].strip(), panel["title"]
    for variable in variables.values():
        if variable["type"] == "query":
            assert variable["datasource"] == DATASOURCE, variable["name"]


def test_every_dashboard_query_selects_what_metrics_exposes(scrape: Scrape) -> None:
    board = dashboard()
    variables = stand_ins(board)
    failures = []
    checked = 0
    for panel, target in targets(board):
        where = f"{panel['title']!r} {target['refId']}"
        try:
            expr = substitute(target["expr"], variables)
        except ValueError as error:
            failures.append(f"{where}: {error}")
            continue
        checked += 1
        listed = problems(expr, scrape)
        failures += [f"{where}: {problem}" for problem in listed]
        if listed:
            continue
        known = labels_of(expr, scrape)
        failures += [f"{where}: legend {{{{{label}}}}} is no label of its series"
                     for label in TEMPLATE_LABEL.findall(target.get("legendFormat", ""))
                     if label not in known]
    assert not failures, "\n".join(failures)
    assert checked >= 10


def test_dashboard_variables_select_what_metrics_exposes(scrape: Scrape) -> None:
    board = dashboard()
    variables = stand_ins(board)
    failures = []
    for variable in board["templating"]["list"]:
        if variable["type"] != "query":
            continue
        query = variable["query"]
        text = query["query"] if isinstance(query, dict) else query
        assert text == variable["definition"], variable["name"]
        failures += [f"${variable['name']}: {problem}" for problem in
                     variable_query_problems(substitute(text, variables), scrape)]
    assert not failures, "\n".join(failures)


def test_every_metric_family_is_on_the_dashboard(scrape: Scrape) -> None:
    """A metric added to /metrics shows up here until a panel shows it too."""
    board = dashboard()
    variables = stand_ins(board)
    used = set().union(*(metric_names(substitute(target["expr"], variables))
                         for _, target in targets(board)))
    missing = sorted(family for family, names in scrape.families.items() if not names & used)
    assert not missing, f"no panel shows {', '.join(missing)}"


# -- the alerting rules ----------------------------------------------------------------------


def test_rules_file_is_a_prometheus_rule_file() -> None:
    document = yaml.safe_load(RULES.read_text(encoding="utf-8"))
    assert set(document) == {"groups"}
    names = [group["name"] for group in document["groups"]]
    assert names and len(names) == len(set(names))
    alerts = [rule["alert"] for rule in rules()]
    assert len(alerts) >= 5 and len(alerts) == len(set(alerts))
    for rule in rules():
        assert set(rule) <= RULE_KEYS and {"alert", "expr"} <= set(rule), rule
        if "for" in rule:
            promql_parser.parse_duration(rule["for"])
        assert rule["labels"]["severity"] in {"critical", "warning", "info"}, rule["alert"]
        assert {"summary", "description"} <= set(rule["annotations"]), rule["alert"]


def test_every_rule_selects_what_metrics_exposes(scrape: Scrape) -> None:
    failures = []
    for rule in rules():
        listed = problems(rule["expr"], scrape)
        failures += [f"{rule['alert']}: {problem}" for problem in listed]
        if listed:
            continue
        known = labels_of(rule["expr"], scrape)
        templates = " ".join([*rule.get("labels", {}).values(),
                              *rule.get("annotations", {}).values()])
        failures += [f"{rule['alert']}: $labels.{label} is no label of its series"
                     for label in ANNOTATION_LABEL.findall(templates) if label not in known]
    assert not failures, "\n".join(failures)


def test_rules_alert_on_what_the_issue_asks() -> None:
    by_name = {rule["alert"]: rule for rule in rules()}
    assert 'status="CONFIRMED"' in by_name["FaultledgerCriticalFaultConfirmed"]["expr"]
    assert "histogram_quantile(0.99" in by_name["FaultledgerCommitLatencyHigh"]["expr"]
    assert by_name["FaultledgerFleetLagHigh"]["for"] == "10m"
    assert metric_names(by_name["FaultledgerDown"]["expr"]) == {"up"}
    assert "increase(" in by_name["FaultledgerStreamDroppingClients"]["expr"]


@pytest.mark.skipif(shutil.which("promtool") is None,
                    reason="needs promtool (Debian's prometheus package)")
def test_promtool_accepts_the_rules() -> None:
    promtool = shutil.which("promtool")
    assert promtool is not None
    done = subprocess.run([promtool, "check", "rules", str(RULES)], capture_output=True,
                          text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stdout + done.stderr


# -- the check itself can fail ---------------------------------------------------------------

CANNED = """\
# HELP faultledger_faults Faults by status and severity
# TYPE faultledger_faults gauge
faultledger_faults{severity="CRITICAL",status="CONFIRMED"} 1.0
faultledger_faults{severity="INFO",status="HEALED"} 0.0
# HELP faultledger_reports_total Reports
# TYPE faultledger_reports_total counter
faultledger_reports_total{event_type="FAILED"} 3.0
# HELP faultledger_commit_seconds Latency
# TYPE faultledger_commit_seconds histogram
faultledger_commit_seconds_bucket{le="0.5"} 2.0
faultledger_commit_seconds_bucket{le="+Inf"} 2.0
faultledger_commit_seconds_count 2.0
faultledger_commit_seconds_sum 0.01
"""


def test_names_come_from_selectors_only() -> None:
    expr = ('histogram_quantile(0.99, sum by (le, job) (rate(a_bucket{kind="x"}[5m]))) '
            '> bool 0.5 and on (job) up offset 1m unless ignoring (le) '
            'sum without (instance) (increase(b_total[1h:1m])) or {__name__="c"} '
            '* on (robot_id) group_left (ledger_id) label_replace(d, "x", "$1", "y", "(.*)")')
    assert metric_names(expr) == {"a_bucket", "up", "b_total", "c", "d"}


@pytest.mark.parametrize(("expr", "words"), [
    ('faultledger_fault{status="CONFIRMED"}',
     "faultledger_fault: no such series in /metrics (did you mean faultledger_faults?)"),
    ("rate(faultledger_reports[5m])", "faultledger_reports: no such series"),
    ("faultledger_commit_seconds", "faultledger_commit_seconds: no such series"),
    ('faultledger_faults{sevrity="CRITICAL"}', "no label 'sevrity'"),
    ('faultledger_faults{status="CONFIMRED"}', "shows no such value"),
    ('faultledger_faults{severity!="FATAL"}', "shows no such value"),
    ('faultledger_faults{status=~"CONF.*|PEND"}', ""),
    ('faultledger_faults{status=~"PENDING|OPEN"}', "the regex matches no value"),
    ("sum by (sevrity) (faultledger_faults)", "by (sevrity): no series below"),
    ("faultledger_faults * on (robot_id) faultledger_reports_total", "on (robot_id)"),
    ('up{robot_id="a"} == 0', "up: label 'robot_id' is not one Prometheus attaches"),
    ('up{job="faultledger"} == 0', ""),
    ('{__name__=~"faultledger_.+"}', "without a literal metric name"),
    ("sum(faultledger_faults", "does not parse"),
    ("vector(1)", "selects no series"),
])
def test_the_check_names_what_is_wrong(expr: str, words: str) -> None:
    found = problems(expr, Scrape.parse(CANNED))
    if words:
        assert any(words in problem for problem in found), found
    else:
        assert found == []


def test_the_check_fails_a_wrong_name_against_the_live_server(scrape: Scrape) -> None:
    good = 'sum(rate(faultledger_reports_total{event_type="FAILED"}[5m]))'
    assert problems(good, scrape) == []
    assert problems(good.replace("reports_total", "report_total"), scrape) == [
        "faultledger_report_total: no such series in /metrics "
        "(did you mean faultledger_reports_total?)"]
    assert problems("faultledger_fleet_lag_seconds{robot=\"a\"}", scrape)


def test_grafana_variables_are_substituted_and_unknown_ones_named() -> None:
    variables = {"job": ".+", "instance": ".+"}
    assert substitute('rate(x{job=~"$job", instance=~"${instance}"}[$__rate_interval])',
                      variables) == 'rate(x{job=~".+", instance=~".+"}[1m])'
    assert substitute('x{job=~"[[job]]"}[$__range]', variables) == 'x{job=~".+"}[1h]'
    with pytest.raises(ValueError, match=r"unknown Grafana variable \$jb"):
        substitute('x{job=~"$jb"}', variables)
