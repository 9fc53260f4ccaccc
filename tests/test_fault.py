"""``new_fault`` is ``Fault(...)`` made cheaper for the state machine: it must build exactly the
tuple ``Fault`` builds, field for field, defaults included, as Fault's fields change."""

from __future__ import annotations

import inspect

from hypothesis import given
from hypothesis import strategies as st

from faultledger.domain.fault import Acknowledgement, Fault, Shelving, new_fault
from faultledger.domain.types import FaultStatus


def test_new_fault_takes_faults_fields_in_order_with_its_defaults() -> None:
    parameters = inspect.signature(new_fault).parameters
    assert tuple(parameters) == Fault._fields
    defaults = {name: p.default for name, p in parameters.items()
                if p.default is not inspect.Parameter.empty}
    assert defaults == Fault._field_defaults


TEXT = st.text(max_size=8)
NUMBER = st.integers(-(2**63), 2**63 - 1)


@given(code=TEXT, severity=NUMBER, description=TEXT, times=st.lists(NUMBER, min_size=8,
       max_size=8), status=st.sampled_from(FaultStatus), sources=st.lists(TEXT).map(tuple),
       failed=st.booleans(), acknowledged=st.none() | st.builds(Acknowledgement, TEXT, TEXT,
       NUMBER, NUMBER), shelved=st.none() | st.builds(Shelving, TEXT, TEXT, NUMBER, NUMBER,
       NUMBER))
def test_new_fault_builds_what_fault_builds(
        code: str, severity: int, description: str, times: list[int], status: FaultStatus,
        sources: tuple[str, ...], failed: bool, acknowledged: Acknowledgement | None,
        shelved: Shelving | None) -> None:
    fields = dict(
        fault_code=code, severity=severity, description=description,
        first_occurred_ns=times[0], last_occurred_ns=times[1], last_passed_ns=times[2],
        occurrence_count=times[3], status=status, reporting_sources=sources,
        debounce_counter=times[4], last_report_failed=failed, first_ever_ns=times[5],
        episode_failures=times[6], total_failures=times[7], confirmed_ns=times[0] ^ 1,
        acknowledged=acknowledged, shelved=shelved)
    made = new_fault(**fields)  # type: ignore[arg-type]
    expected = Fault(**fields)  # type: ignore[arg-type]
    assert type(made) is Fault
    assert made == expected
    assert made._asdict() == expected._asdict()
    short = new_fault(code, severity, description, times[0], times[1], times[2], times[3],
                      status, sources, times[4])
    assert short == Fault(code, severity, description, times[0], times[1], times[2], times[3],
                          status, sources, times[4])
