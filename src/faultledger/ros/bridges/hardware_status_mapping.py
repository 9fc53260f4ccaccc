"""Hardware status → fault transitions: the pure part of the hardware-status bridge (no rclpy).

A ros2_control hardware component publishes ``HardwareStatus`` (the control_msgs layout of
ros2_control's hardware status proposal, shipped by us as ``hardware_status_msgs``) at 1-50 Hz:
the full state of each of its devices, every time. Faults are about *changes*: this module keeps
one state per (hardware, device, condition) and turns each message into edge transitions, FAILED
when a condition is entered and PASSED when it is left. A button held for a minute at 50 Hz is
one FAILED, so counting e-stops per shift is counting FAILED reports.

Messages are read by field name (``getattr``), never by type, so control_msgs' own
``HardwareStatus`` (where a distribution has it) works as well as ours. The documented contract
(the condition table) is ``docs/bridges/hardware_status.md``; ``CONDITIONS`` below is its source.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from pydantic import BaseModel, Field

from faultledger.ros.bridges.codes import fault_code
from faultledger.ros.bridges.settings import normalise

DEFAULT_MESSAGE_TYPE = "hardware_status_msgs/msg/HardwareStatus"
DEFAULT_TOPIC = "/hardware_status"
TOPIC_SUFFIX = "/hardware_status"
"""ros2_control publishes each component's status on ``/<component>/hardware_status``."""

# GenericState constants (values of the proposal, control_msgs PR #240).
HEALTH_UNKNOWN, HEALTH_OK, HEALTH_DEGRADED, HEALTH_WARNING, HEALTH_ERROR, HEALTH_FATAL = range(6)
ERROR_NONE, ERROR_UNKNOWN, ERROR_HW, ERROR_SW, ERROR_OVER_TRAVEL = range(5)
EMERGENCY_STOP_HW, EMERGENCY_STOP_SW, PROTECTIVE_STOP_HW, PROTECTIVE_STOP_SW = 5, 6, 7, 8
SAFETY_STOP, CALIBRATION_REQUIRED = 9, 10
(POWER_UNKNOWN, POWER_OFF, POWER_STANDBY, POWER_ON, POWER_SLEEP, POWER_ERROR, POWER_LEVEL_LOW,
 POWER_LEVEL_CRITICAL, POWER_CHARGING, POWER_CHARGING_ERROR) = range(10)
CONNECT_UNKNOWN, CONNECT_UP, CONNECT_DOWN, CONNECT_FAILURE, CONNECTION_SLOW = range(5)
# CANopenState / EtherCATState constants.
NMT_STATES = frozenset({0, 4, 5, 127})
DSP402_FAULT_REACTION_ACTIVE, DSP402_FAULT = 6, 7
DSP402_STATES = frozenset(range(8))

HEALTH_NAMES = ("UNKNOWN", "OK", "DEGRADED", "WARNING", "ERROR", "FATAL")
POWER_NAMES = ("UNKNOWN", "OFF", "STANDBY", "ON", "SLEEP", "ERROR", "LEVEL_LOW", "LEVEL_CRITICAL",
               "CHARGING", "CHARGING_ERROR")
CONNECT_NAMES = ("UNKNOWN", "UP", "DOWN", "FAILURE", "SLOW")
AL_STATE_NAMES = {1: "INIT", 2: "PREOP", 3: "BOOTSTRAP", 4: "SAFEOP", 8: "OP"}

MAX_DESCRIPTION = 1000
"""Descriptions are cut here (the ledger allows 4096): they are for humans, not for parsing."""


def _sev(default: int) -> Any:
    return Field(default=default, ge=0, le=3)


class Severities(BaseModel):
    """Severity (0 INFO, 1 WARN, 2 ERROR, 3 CRITICAL) reported for each condition."""

    emergency_stop: int = _sev(3)
    emergency_stop_sw: int = _sev(3)
    protective_stop: int = _sev(2)
    protective_stop_sw: int = _sev(2)
    safety_stop: int = _sev(2)
    error_unknown: int = _sev(2)
    error_hw: int = _sev(2)
    error_sw: int = _sev(2)
    over_travel: int = _sev(2)
    calibration_required: int = _sev(1)
    health_error: int = _sev(2)
    health_fatal: int = _sev(3)
    power_error: int = _sev(2)
    battery_low: int = _sev(1)
    battery_critical: int = _sev(2)
    charging_error: int = _sev(1)
    connection_down: int = _sev(2)
    connection_failure: int = _sev(2)
    connection_slow: int = _sev(1)
    ethercat_error: int = _sev(2)
    canopen_emcy: int = _sev(2)
    canopen_drive_fault: int = _sev(2)
    vda5050_error: int = _sev(2)


class Settings(BaseModel):
    """``config/hardware_status.yaml``: every key optional; these defaults are the contract."""

    topics: list[str] = Field(default_factory=lambda: [DEFAULT_TOPIC])
    """Topics always subscribed."""
    discover: bool = True
    """Also subscribe to every topic ending in ``/hardware_status`` of ``message_type``."""
    rescan_period_sec: float = Field(default=2.0, gt=0)
    message_type: str = Field(default=DEFAULT_MESSAGE_TYPE,
                              pattern=r"^[A-Za-z_][A-Za-z0-9_]*/msg/[A-Za-z_][A-Za-z0-9_]*$")
    """``pkg/msg/Type``; control_msgs' own type works too (fields are read by name)."""
    code_prefix: str = Field(default="HW", pattern=r"^[A-Za-z0-9_]{0,32}$")
    source_id: str = Field(default="", max_length=1024)
    """Source of the reports; empty: the message's ``hardware_id``."""
    max_devices: int = Field(default=256, gt=0)
    """Devices read from one message; more are ignored with a warning."""
    max_entries: int = Field(default=32, gt=0)
    """Entries read from each per-device array (states, error_domain); more: warning."""
    max_hardware: int = Field(default=64, gt=0)
    """Hardware ids tracked; messages of further ids are ignored with a warning."""
    warn_interval_sec: float = Field(default=10.0, ge=0)
    """One warning per kind of problem and source in this interval."""
    queue_depth: int = Field(default=100, gt=0)
    severities: dict[str, Any] = Field(default_factory=dict)
    """Overrides of ``Severities`` by name; bad entries fall back to the default with a warning."""


def resolve_severities(raw: dict[str, Any], warn: Callable[[str], None]) -> Severities:
    """``severities:`` overrides merged over the defaults; a bad entry keeps its default and is
    named in a warning, an unknown name is warned about (the bridge never stops on config)."""
    return normalise(Severities, raw, warn, "hardware_status.severities")


@dataclass(frozen=True)
class Condition:
    """One row of the documented table: a code suffix, its family and severity setting."""

    suffix: str
    family: str
    severity_key: str
    meaning: str


ERROR_DOMAIN_CONDITIONS: dict[int, Condition] = {
    ERROR_UNKNOWN: Condition("ERROR_UNKNOWN", "error_domain", "error_unknown",
                             "error_domain contains ERROR_UNKNOWN"),
    ERROR_HW: Condition("ERROR_HW", "error_domain", "error_hw", "error_domain contains ERROR_HW"),
    ERROR_SW: Condition("ERROR_SW", "error_domain", "error_sw", "error_domain contains ERROR_SW"),
    ERROR_OVER_TRAVEL: Condition("OVER_TRAVEL", "error_domain", "over_travel",
                                 "error_domain contains ERROR_OVER_TRAVEL"),
    EMERGENCY_STOP_HW: Condition("EMERGENCY_STOP", "error_domain", "emergency_stop",
                                 "error_domain contains EMERGENCY_STOP_HW"),
    EMERGENCY_STOP_SW: Condition("EMERGENCY_STOP_SW", "error_domain", "emergency_stop_sw",
                                 "error_domain contains EMERGENCY_STOP_SW"),
    PROTECTIVE_STOP_HW: Condition("PROTECTIVE_STOP", "error_domain", "protective_stop",
                                  "error_domain contains PROTECTIVE_STOP_HW"),
    PROTECTIVE_STOP_SW: Condition("PROTECTIVE_STOP_SW", "error_domain", "protective_stop_sw",
                                  "error_domain contains PROTECTIVE_STOP_SW"),
    SAFETY_STOP: Condition("SAFETY_STOP", "error_domain", "safety_stop",
                           "error_domain contains SAFETY_STOP"),
    CALIBRATION_REQUIRED: Condition("CALIBRATION_REQUIRED", "error_domain", "calibration_required",
                                    "error_domain contains CALIBRATION_REQUIRED"),
}
HEALTH = Condition("HEALTH_ERROR", "health", "health_error / health_fatal",
                   "health_status ERROR (health_error) or FATAL (health_fatal)")
HEALTH_SEVERITY = {HEALTH_ERROR: "health_error", HEALTH_FATAL: "health_fatal"}
POWER_CONDITIONS: dict[int, Condition] = {
    POWER_ERROR: Condition("POWER_ERROR", "power", "power_error", "power_state POWER_ERROR"),
    POWER_LEVEL_LOW: Condition("BATTERY_LOW", "power", "battery_low",
                               "power_state POWER_LEVEL_LOW"),
    POWER_LEVEL_CRITICAL: Condition("BATTERY_CRITICAL", "power", "battery_critical",
                                    "power_state POWER_LEVEL_CRITICAL"),
    POWER_CHARGING_ERROR: Condition("CHARGING_ERROR", "power", "charging_error",
                                    "power_state POWER_CHARGING_ERROR"),
}
CONNECTION_LOST = Condition("CONNECTION_LOST", "connectivity",
                            "connection_down / connection_failure",
                            "connectivity_status CONNECT_DOWN (connection_down) or "
                            "CONNECT_FAILURE (connection_failure)")
CONNECTION_LOST_SEVERITY = {CONNECT_DOWN: "connection_down", CONNECT_FAILURE: "connection_failure"}
CONNECTION_SLOW_CONDITION = Condition("CONNECTION_SLOW", "connectivity", "connection_slow",
                                      "connectivity_status CONNECTION_SLOW")
ETHERCAT_ERROR = Condition("ETHERCAT_ERROR", "ethercat", "ethercat_error",
                           "an ethercat_states entry with has_error true")
CANOPEN_EMCY = Condition("CANOPEN_EMCY_<XXXX>", "canopen_emcy", "canopen_emcy",
                         "a canopen_states entry with last_emcy_code XXXX (hex, non-zero)")
CANOPEN_DRIVE_FAULT = Condition("CANOPEN_DRIVE_FAULT", "canopen_drive", "canopen_drive_fault",
                                "a canopen_states entry with dsp_402_state FAULT or "
                                "FAULT_REACTION_ACTIVE")
VDA5050_ERROR = Condition("VDA5050_ERROR", "vda5050", "vda5050_error",
                          "a vda5050_states entry with a non-empty error_type")

CONDITIONS: tuple[Condition, ...] = (
    *ERROR_DOMAIN_CONDITIONS.values(), HEALTH, *POWER_CONDITIONS.values(), CONNECTION_LOST,
    CONNECTION_SLOW_CONDITION, ETHERCAT_ERROR, CANOPEN_EMCY, CANOPEN_DRIVE_FAULT, VDA5050_ERROR)
"""Every condition, in the order of the documented table."""


# -- reading messages by field name ---------------------------------------------------------------
def _seq(message: Any, name: str) -> Sequence[Any]:
    value = getattr(message, name, None)
    if value is None or isinstance(value, (str, bytes)):
        return ()
    try:
        return list(value)
    except TypeError:
        return ()


def _int(message: Any, name: str, default: int = 0) -> int:
    value = getattr(message, name, default)
    if isinstance(value, (bytes, bytearray)):  # uint8 read through an older binding
        return value[0] if len(value) == 1 else default
    try:
        return int(value)
    except (TypeError, ValueError):
        return default


def _str(message: Any, name: str) -> str:
    value = getattr(message, name, "")
    return value if isinstance(value, str) else str(value)


def _generic_states(device: Any) -> Sequence[Any]:
    """``generic_hardware_status`` (the merged layout), or ``hardware_status`` (an earlier
    revision of control_msgs PR #240 named the field so)."""
    if hasattr(device, "generic_hardware_status"):
        return _seq(device, "generic_hardware_status")
    return _seq(device, "hardware_status")


# -- evaluation ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Active:
    severity: int
    description: str


@dataclass
class Observation:
    """What one device's entry says: active conditions by code suffix, and which families it
    evaluated (a family not evaluated keeps its previous state: nothing is assumed)."""

    active: dict[str, Active] = field(default_factory=dict)
    families: dict[str, str] = field(default_factory=dict)
    """suffix → family, for the active ones."""
    evaluated: set[str] = field(default_factory=set)
    warnings: list[tuple[str, str]] = field(default_factory=list)

    def add(self, suffix: str, family: str, severity: int, description: str) -> None:
        """Several entries may name the same condition: the highest severity wins."""
        old = self.active.get(suffix)
        if old is None or severity > old.severity:
            self.active[suffix] = Active(severity, description)
            self.families[suffix] = family


@dataclass(frozen=True)
class Transition:
    """One report to make: FAILED (``failed``) or PASSED of ``code`` on behalf of ``source_id``."""

    code: str
    failed: bool
    severity: int
    description: str
    source_id: str
    hardware_id: str
    device_id: str
    suffix: str


def _limited(items: Sequence[Any], limit: int, what: str, where: str,
             warnings: list[tuple[str, str]]) -> Sequence[Any]:
    if len(items) > limit:
        warnings.append((f"too_many:{what}:{where}",
                         f"{where}: {len(items)} {what}; only the first {limit} are read"))
        return items[:limit]
    return items


def observe_device(device: Any, where: str, severities: Severities,
                   max_entries: int) -> Observation:
    """Evaluate every condition of one ``HardwareDeviceStatus`` (read by field name)."""
    obs = Observation()
    sev = severities.model_dump()
    generic = _limited(_generic_states(device), max_entries, "generic states", where, obs.warnings)
    if generic:
        _observe_generic(generic, where, sev, max_entries, obs)
    canopen = _limited(_seq(device, "canopen_states"), max_entries, "canopen states", where,
                       obs.warnings)
    if canopen:
        _observe_canopen(canopen, where, sev, obs)
    ethercat = _limited(_seq(device, "ethercat_states"), max_entries, "ethercat states", where,
                        obs.warnings)
    if ethercat:
        obs.evaluated.add("ethercat")
        errors = [e for e in ethercat if bool(getattr(e, "has_error", False))]
        if errors:
            text = "; ".join(_ethercat_text(e) for e in errors)
            obs.add(ETHERCAT_ERROR.suffix, "ethercat", sev["ethercat_error"],
                    f"{where}: EtherCAT error: {text}")
    vda = _limited(_seq(device, "vda5050_states"), max_entries, "vda5050 states", where,
                   obs.warnings)
    if vda:
        obs.evaluated.add("vda5050")
        errors = [v for v in vda if _str(v, "error_type")]
        if errors:
            text = "; ".join(f"{_str(v, 'error_type')}: {_str(v, 'error_description')}".rstrip(": ")
                             for v in errors)
            obs.add(VDA5050_ERROR.suffix, "vda5050", sev["vda5050_error"],
                    f"{where}: VDA 5050 error {text}")
    return obs


def _unknown(obs: Observation, where: str, what: str, value: object) -> None:
    obs.warnings.append((f"unknown:{what}:{where}",
                         f"{where}: unknown {what} value {value!r} ignored"))


def _observe_generic(states: Sequence[Any], where: str, sev: dict[str, int], max_entries: int,
                     obs: Observation) -> None:
    obs.evaluated.add("error_domain")
    for state in states:
        domains = _limited(_seq(state, "error_domain"), max_entries, "error_domain values", where,
                           obs.warnings)
        for raw in domains:
            try:
                value = int(raw)
            except (TypeError, ValueError):
                _unknown(obs, where, "error_domain", raw)
                continue
            condition = ERROR_DOMAIN_CONDITIONS.get(value)
            if condition is not None:
                obs.add(condition.suffix, condition.family, sev[condition.severity_key],
                        f"{where}: {condition.meaning}")
            elif value != ERROR_NONE:
                _unknown(obs, where, "error_domain", value)
        health = _int(state, "health_status")
        if health < len(HEALTH_NAMES):
            obs.evaluated.add("health")
            if health in HEALTH_SEVERITY:
                obs.add(HEALTH.suffix, "health", sev[HEALTH_SEVERITY[health]],
                        f"{where}: health {HEALTH_NAMES[health]}{_details(state)}")
        else:
            _unknown(obs, where, "health_status", health)
        power = _int(state, "power_state")
        if power < len(POWER_NAMES):
            obs.evaluated.add("power")
            condition = POWER_CONDITIONS.get(power)
            if condition is not None:
                obs.add(condition.suffix, "power", sev[condition.severity_key],
                        f"{where}: power {POWER_NAMES[power]}{_details(state)}")
        else:
            _unknown(obs, where, "power_state", power)
        connect = _int(state, "connectivity_status")
        if connect < len(CONNECT_NAMES):
            obs.evaluated.add("connectivity")
            if connect in CONNECTION_LOST_SEVERITY:
                obs.add(CONNECTION_LOST.suffix, "connectivity",
                        sev[CONNECTION_LOST_SEVERITY[connect]],
                        f"{where}: connectivity {CONNECT_NAMES[connect]}{_details(state)}")
            elif connect == CONNECTION_SLOW:
                obs.add(CONNECTION_SLOW_CONDITION.suffix, "connectivity", sev["connection_slow"],
                        f"{where}: connectivity SLOW{_details(state)}")
        else:
            _unknown(obs, where, "connectivity_status", connect)


def _details(state: Any) -> str:
    """Vendor and state_details appended to descriptions: what a technician wants to read."""
    vendor = " ".join(x for x in (_str(state, "manufacturer"), _str(state, "model")) if x)
    pairs = [f"{_str(kv, 'key')}={_str(kv, 'value')}" for kv in _seq(state, "state_details")[:8]]
    text = ", ".join(x for x in (vendor, *pairs) if x)
    return f" ({text})" if text else ""


def _ethercat_text(entry: Any) -> str:
    al_state = _int(entry, "al_state")
    state = AL_STATE_NAMES.get(al_state, str(al_state))
    return (f"slave {_int(entry, 'slave_position')} al_state {state} "
            f"al_status_code 0x{_int(entry, 'al_status_code'):04X}")


def _observe_canopen(states: Sequence[Any], where: str, sev: dict[str, int],
                     obs: Observation) -> None:
    obs.evaluated.add("canopen_emcy")
    for state in states:
        node = _int(state, "node_id")
        emcy = _int(state, "last_emcy_code")
        if emcy < 0 or emcy > 0xFFFFFFFF:
            _unknown(obs, where, "last_emcy_code", emcy)
        elif emcy:
            obs.add(f"CANOPEN_EMCY_{emcy:04X}", "canopen_emcy", sev["canopen_emcy"],
                    f"{where}: CANopen node {node} EMCY 0x{emcy:04X}")
        nmt = _int(state, "nmt_state")
        if nmt not in NMT_STATES:
            _unknown(obs, where, "nmt_state", nmt)
        dsp = _int(state, "dsp_402_state")
        if dsp in DSP402_STATES:
            obs.evaluated.add("canopen_drive")
            if dsp in (DSP402_FAULT, DSP402_FAULT_REACTION_ACTIVE):
                name = "FAULT" if dsp == DSP402_FAULT else "FAULT_REACTION_ACTIVE"
                obs.add(CANOPEN_DRIVE_FAULT.suffix, "canopen_drive", sev["canopen_drive_fault"],
                        f"{where}: CANopen node {node} CiA 402 state {name}")
        else:
            _unknown(obs, where, "dsp_402_state", dsp)


# -- the edge-triggered state ----------------------------------------------------------------------
@dataclass
class _Held:
    family: str
    severity: int


class HardwareStatusMapper:
    """Keeps the state per (hardware, device, condition) and turns messages into transitions.

    A condition is FAILED once on entry and PASSED once on exit. While it holds, a FAILED is sent
    again only when its severity rises (health ERROR → FATAL). A device or a whole block
    (e.g. ``ethercat_states``) missing from a message changes nothing: nothing is assumed.
    """

    def __init__(self, settings: Settings, severities: Severities) -> None:
        self.settings = settings
        self.severities = severities
        prefix = settings.code_prefix.upper()
        self._prefix = f"{prefix}_" if prefix else ""
        """Codes are ``<PREFIX>_<HW>_<DEVICE>_<SUFFIX>`` (``codes.fault_code``)."""
        self._state: dict[str, dict[str, dict[str, _Held]]] = {}
        """hardware_id → device_id → suffix → held condition."""

    def held(self, hardware_id: str, device_id: str) -> dict[str, int]:
        """The conditions currently held for a device (suffix → severity); for tests/inspection."""
        device = self._state.get(hardware_id, {}).get(device_id, {})
        return {suffix: h.severity for suffix, h in device.items()}

    def update(self, message: Any) -> tuple[list[Transition], list[tuple[str, str]]]:
        """Transitions caused by one ``HardwareStatus`` and warnings (throttle key, text)."""
        warnings: list[tuple[str, str]] = []
        hardware_id = _str(message, "hardware_id")
        if not hardware_id:
            warnings.append(("empty_hardware_id", "HardwareStatus with an empty hardware_id "
                                                  "ignored"))
            return [], warnings
        hardware = self._state.get(hardware_id)
        if hardware is None:
            if len(self._state) >= self.settings.max_hardware:
                warnings.append(("max_hardware", f"hardware {hardware_id!r} ignored: already "
                                 f"tracking max_hardware={self.settings.max_hardware} ids"))
                return [], warnings
            hardware = self._state[hardware_id] = {}
        source = self.settings.source_id or hardware_id[:1024]
        devices = _limited(_seq(message, "hardware_device_states"), self.settings.max_devices,
                           "devices", hardware_id, warnings)
        transitions: list[Transition] = []
        seen: set[str] = set()
        for device in devices:
            device_id = _str(device, "device_id")
            if not device_id:
                warnings.append((f"empty_device_id:{hardware_id}",
                                 f"{hardware_id}: device with an empty device_id ignored"))
                continue
            if device_id in seen:
                warnings.append((f"duplicate_device:{hardware_id}",
                                 f"{hardware_id}: device {device_id!r} appears twice; only the "
                                 f"first entry is read"))
                continue
            seen.add(device_id)
            where = f"{hardware_id}/{device_id}"
            obs = observe_device(device, where, self.severities, self.settings.max_entries)
            warnings.extend(obs.warnings)
            held = hardware.setdefault(device_id, {})
            transitions.extend(self._apply(hardware_id, device_id, source, obs, held))
            if not held:
                del hardware[device_id]
        return transitions, warnings

    def _apply(self, hardware_id: str, device_id: str, source: str, obs: Observation,
               held: dict[str, _Held]) -> Iterable[Transition]:
        for suffix, active in obs.active.items():
            previous = held.get(suffix)
            if previous is None or active.severity > previous.severity:
                held[suffix] = _Held(obs.families[suffix], active.severity)
                yield Transition(fault_code(hardware_id, device_id, prefix=self._prefix,
                                            suffix=suffix), True, active.severity,
                                 active.description[:MAX_DESCRIPTION], source, hardware_id,
                                 device_id, suffix)
        for suffix in [s for s, h in held.items()
                       if h.family in obs.evaluated and s not in obs.active]:
            del held[suffix]
            yield Transition(fault_code(hardware_id, device_id, prefix=self._prefix,
                                        suffix=suffix), False, 0, "", source, hardware_id,
                             device_id, suffix)
