"""`faultledger serve` logs the policy's warnings when it opens the ledger (issue 21, item 5;
medkit #276): a code pattern and a source prefix that set one field differently, and a fault
whose recorded reporting sources resolve to different thresholds. They never stop it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from faultledger import FaultLedger, Policy

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory

POLICY = {"code_overrides": {"HW_*": {"confirmation_threshold": -3}},
          "overrides": {"/safety": {"confirmation_threshold": -1}}}
T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)


def test_serve_logs_the_policy_and_ledger_warnings_and_serves(manager: ManagerFactory,
                                                               tmp_path: Path) -> None:
    db = tmp_path / "faults.db"
    with FaultLedger.open(f"sqlite:///{db}", policy=Policy.model_validate(POLICY),
                          background=False) as ledger:
        for seconds, source in ((0, "/arm/driver"), (1, "/safety/estop")):
            assert ledger.report("HW_ARM_EMERGENCY_STOP", "FAILED", 2, "", source,
                                 at=T0 + timedelta(seconds=seconds)).accepted
    config = tmp_path / "faultledger.yaml"
    config.write_text(yaml.safe_dump({"policy": POLICY, "http": {"tokens_file": None}}))

    served = manager("--config", str(config), db=db)
    log = " ".join(served.stderr_text().split())

    assert "policy: code_overrides 'HW_*' sets confirmation_threshold -3, overrides '/safety' "\
        "sets -1" in log, served.describe()
    assert "policy: HW_ARM_EMERGENCY_STOP was reported by 2 sources under different " \
        "thresholds: '/arm/driver': confirmation_threshold -3 (code_overrides 'HW_*'); " \
        "'/safety/estop': confirmation_threshold -1 (overrides '/safety')" in log, \
        served.describe()
    assert served.stop() == 0
