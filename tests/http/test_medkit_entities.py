"""The ros2_medkit gateway's per-entity fault routes through a real `faultledger http`, called
as medkit's generated client calls them (selfpatch/ros2_medkit_clients, spec/openapi.yaml:
listAppFaults, getAppFault, clearAppFault, clearAllAppFaults and the same for components,
areas and functions): the paths, no query parameters on the DELETEs, 204 with no body, and
SOVD GenericError bodies (``error_code``, ``message``, ``parameters``) on 404.

A fault belongs to an entity when one of its reporting sources is the id or ends in ``/id``
(``list_faults_for_entity``); an entity no fault was ever reported by is unknown (404)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.http.conftest import Server, start_server, write_config

KINDS = ("apps", "components", "areas", "functions")
OPERATOR = "flt_entity-test-operator-token"
VIEWER = "flt_entity-test-viewer-token"


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    folder = tmp_path_factory.mktemp("entities")
    tokens = [{"name": "alice", "role": "operator",
               "sha256": hashlib.sha256(OPERATOR.encode()).hexdigest()},
              {"name": "wall-display", "role": "viewer",
               "sha256": hashlib.sha256(VIEWER.encode()).hexdigest()}]
    config = write_config(folder / "config.yaml", http={"tokens": tokens},
                          extra={"policy": {"confirmation_threshold": -3}})
    running = start_server(folder / "faults.db", config=config)
    running.client.headers.update(bearer(OPERATOR))
    yield running
    running.stop()


def report(server: Server, code: str, source: str, event_type: str = "FAILED",
           severity: int = 3) -> None:
    answer = server.client.post("/api/v1/reports", json={
        "fault_code": code, "event_type": event_type, "severity": severity,
        "source_id": source, "description": f"{code} from {source}"})
    assert answer.status_code == 200 and answer.json()["accepted"], answer.text


def status_of(server: Server, code: str) -> str:
    found: str = server.client.get(f"/api/v1/faults/{code}").json()["x-medkit"]["status_raw"]
    return found


def clears(server: Server, code: str) -> list[dict[str, Any]]:
    """The payloads of the fault_cleared records of ``code``, oldest first."""
    items = server.client.get("/api/v1/history", params={"code": code,
                                                         "kind": "fault_cleared"}).json()
    return [record["payload"] for record in items["items"]]


def assert_entity_not_found(answer: httpx.Response, entity_id: str) -> None:
    assert answer.status_code == 404, answer.text
    body = answer.json()
    assert body["reason"] == "not_found"
    assert body["error_code"] == "entity-not-found"  # the gateway's ERR_ENTITY_NOT_FOUND
    assert body["message"] == "Entity not found"
    assert body["parameters"]["entity_id"] == entity_id


def assert_fault_not_found(answer: httpx.Response, kind: str, entity_id: str,
                           code: str) -> None:
    assert answer.status_code == 404, answer.text
    body = answer.json()
    assert body["reason"] == "not_found" and body["error_code"] == "resource-not-found"
    assert body["message"] == f"Fault not found: {code}"
    assert body["parameters"] == {f"{kind.removesuffix('s')}_id": entity_id,
                                  "fault_code": code}


@pytest.mark.parametrize("kind", KINDS)
def test_list_and_get_per_entity(server: Server, kind: str) -> None:
    mine, other = f"LG_{kind.upper()}_MINE", f"LG_{kind.upper()}_OTHER"
    report(server, mine, f"/robot/{kind}_lidar")
    report(server, other, f"/robot/{kind}_camera")
    listed = server.client.get(f"/api/v1/{kind}/{kind}_lidar/faults")
    assert listed.status_code == 200
    assert [i["fault_code"] for i in listed.json()["items"]] == [mine]
    assert listed.json()["x-medkit"]["entity_id"] == f"{kind}_lidar"
    detail = server.client.get(f"/api/v1/{kind}/{kind}_lidar/faults/{mine}")
    assert detail.status_code == 200 and detail.json()["item"]["code"] == mine
    assert_fault_not_found(server.client.get(f"/api/v1/{kind}/{kind}_lidar/faults/{other}"),
                           kind, f"{kind}_lidar", other)
    assert_fault_not_found(server.client.get(f"/api/v1/{kind}/{kind}_lidar/faults/NEVER"),
                           kind, f"{kind}_lidar", "NEVER")
    # "robot" is a prefix of the sources, not a last segment: no fault belongs to it
    assert_entity_not_found(server.client.get(f"/api/v1/{kind}/robot/faults"), "robot")
    assert_entity_not_found(server.client.get(f"/api/v1/{kind}/ghost/faults/{mine}"), "ghost")
    bad = server.client.get(f"/api/v1/{kind}/{kind}_lidar/faults", params={"status": "bogus"})
    assert bad.status_code == 400 and bad.json()["message"] == "Invalid status parameter value"


def test_an_entity_stays_known_after_its_faults_are_cleared(server: Server) -> None:
    report(server, "KNOWN_ONE", "/base/bumper")
    assert server.client.delete("/api/v1/faults/KNOWN_ONE").status_code == 204
    listed = server.client.get("/api/v1/components/bumper/faults")
    assert listed.status_code == 200 and listed.json()["items"] == []
    everything = server.client.get("/api/v1/components/bumper/faults", params={"status": "all"})
    assert [i["status"] for i in everything.json()["items"]] == ["CLEARED"]
    detail = server.client.get("/api/v1/components/bumper/faults/KNOWN_ONE")
    assert detail.status_code == 200
    assert detail.json()["item"]["status"]["aggregatedStatus"] == "cleared"


@pytest.mark.parametrize("kind", KINDS)
def test_clear_one_fault_of_an_entity(server: Server, kind: str) -> None:
    mine, other = f"C1_{kind.upper()}_MINE", f"C1_{kind.upper()}_OTHER"
    entity = f"{kind}_gripper"
    report(server, mine, f"/arm/{entity}")
    report(server, other, f"/arm/{kind}_wrist")
    path = f"/api/v1/{kind}/{entity}/faults/{mine}"

    refused = server.client.delete(path, headers=bearer(VIEWER))
    assert refused.status_code == 403 and refused.json()["reason"] == "forbidden"
    assert "wall-display" in refused.json()["message"]
    assert status_of(server, mine) == "CONFIRMED" and clears(server, mine) == []
    assert server.client.delete(path, headers={"Authorization": ""}).status_code == 401

    foreign = server.client.delete(f"/api/v1/{kind}/{entity}/faults/{other}")
    assert_fault_not_found(foreign, kind, entity, other)
    assert status_of(server, other) == "CONFIRMED"  # another entity's fault is untouched
    assert_fault_not_found(server.client.delete(f"/api/v1/{kind}/{entity}/faults/NEVER"),
                           kind, entity, "NEVER")
    assert_entity_not_found(server.client.delete(f"/api/v1/{kind}/ghost/faults/{mine}"),
                            "ghost")

    cleared = server.client.delete(path)  # as medkit's client: no query, no body
    assert cleared.status_code == 204 and cleared.content == b""
    assert status_of(server, mine) == "CLEARED"
    assert clears(server, mine) == [{"actor": "alice", "fault_code": mine, "reason": ""}]

    report(server, mine, f"/arm/{entity}")
    again = server.client.delete(path, params={"reason": "gripper replaced"})
    assert again.status_code == 204
    assert clears(server, mine)[-1] == {"actor": "alice", "fault_code": mine,
                                        "reason": "gripper replaced"}


@pytest.mark.parametrize("kind", KINDS)
def test_clear_every_fault_of_an_entity(server: Server, kind: str) -> None:
    entity = f"{kind}_drive"
    confirmed, pending, passing = (f"CA_{kind.upper()}_{name}"
                                   for name in ("CONFIRMED", "PENDING", "PASSING"))
    report(server, confirmed, f"/base/{entity}")
    report(server, pending, f"/base/{entity}", severity=1)  # one FAILED of three: PREFAILED
    report(server, passing, entity, severity=1)  # the id itself is a source of the entity
    report(server, passing, entity, "PASSED")
    report(server, passing, entity, "PASSED")
    neighbour = f"CA_{kind.upper()}_NEIGHBOUR"
    report(server, neighbour, f"/base/{kind}_steering")
    assert [status_of(server, c) for c in (confirmed, pending, passing)] == [
        "CONFIRMED", "PREFAILED", "PREPASSED"]
    path = f"/api/v1/{kind}/{entity}/faults"

    assert server.client.delete(path, headers=bearer(VIEWER)).status_code == 403
    assert status_of(server, confirmed) == "CONFIRMED" and clears(server, confirmed) == []
    assert_entity_not_found(server.client.delete(f"/api/v1/{kind}/ghost/faults"), "ghost")

    cleared = server.client.delete(path)  # as medkit's client: no query, no body
    assert cleared.status_code == 204 and cleared.content == b""
    # the gateway clears what its list shows by default: PREFAILED and CONFIRMED
    assert [status_of(server, c) for c in (confirmed, pending, passing)] == [
        "CLEARED", "CLEARED", "PREPASSED"]
    assert status_of(server, neighbour) == "CONFIRMED"
    assert clears(server, confirmed) == [{"actor": "alice", "fault_code": confirmed,
                                          "reason": ""}]
    assert server.client.get(path).json()["items"] == []

    everything = server.client.delete(path, params={"status": "all", "reason": "overhaul"})
    assert everything.status_code == 204
    assert status_of(server, passing) == "CLEARED"
    assert clears(server, passing) == [{"actor": "alice", "fault_code": passing,
                                        "reason": "overhaul"}]
    assert len(clears(server, confirmed)) == 1  # a CLEARED fault is not cleared twice
    bad = server.client.delete(path, params={"status": "Pending"})
    assert bad.status_code == 400 and bad.json()["parameters"]["parameter"] == "status"


def test_openapi_names_the_routes_as_the_gateway(server: Server) -> None:
    """A client generated from our /openapi.json has medkit's operations and parameters."""
    paths = server.client.get("/openapi.json").json()["paths"]
    for kind in KINDS:
        singular = kind.removesuffix("s")
        title = singular.capitalize()
        listing = paths[f"/api/v1/{kind}/{{{singular}_id}}/faults"]
        one = paths[f"/api/v1/{kind}/{{{singular}_id}}/faults/{{fault_code}}"]
        assert listing["get"]["operationId"] == f"list{title}Faults"
        assert listing["delete"]["operationId"] == f"clearAll{title}Faults"
        assert one["get"]["operationId"] == f"get{title}Fault"
        assert one["delete"]["operationId"] == f"clear{title}Fault"
        assert "204" in one["delete"]["responses"] and "204" in listing["delete"]["responses"]
        names = {p["name"] for p in one["delete"]["parameters"] if p["in"] == "path"}
        assert names == {f"{singular}_id", "fault_code"}
