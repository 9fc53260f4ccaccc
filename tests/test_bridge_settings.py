"""Bridge settings: a bad value in a bridge's YAML is replaced by its default with a warning
that names it; only an unreadable or malformed file is an error."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import BaseModel, Field

from faultledger.errors import ConfigError
from faultledger.ros.bridges.settings import normalise, read_yaml


class Example(BaseModel):
    rescan_period_sec: float = Field(default=2.0, gt=0)
    dedup_capacity: int = Field(default=4096, ge=1)
    code_prefix: str = "ACTION"
    exclude_actions: list[str] = Field(default_factory=list)


def test_valid_values_pass_without_warnings() -> None:
    warnings: list[str] = []
    settings = normalise(Example, {"rescan_period_sec": 0.5, "exclude_actions": ["/x"]},
                         warnings.append)
    assert settings == Example(rescan_period_sec=0.5, exclude_actions=["/x"])
    assert warnings == []


def test_each_bad_value_falls_back_to_its_default_and_is_named() -> None:
    warnings: list[str] = []
    settings = normalise(Example, {"rescan_period_sec": -1.0, "dedup_capacity": "many",
                                   "code_prefix": "NAV"}, warnings.append, "action_status")
    assert settings == Example(code_prefix="NAV")
    assert sorted(warnings) == [
        "action_status.dedup_capacity='many' is invalid (Input should be a valid integer, "
        "unable to parse string as an integer); using 4096",
        "action_status.rescan_period_sec=-1.0 is invalid (Input should be greater than 0); "
        "using 2.0",
    ]


def test_unknown_keys_are_ignored_with_a_warning() -> None:
    warnings: list[str] = []
    assert normalise(Example, {"rescan_period": 1}, warnings.append) == Example()
    assert warnings == ["rescan_period is not a setting of this bridge; ignored"]


def test_read_yaml_errors_are_specific(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"cannot read bridge config .*missing\.yaml"):
        read_yaml(tmp_path / "missing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="is not valid YAML"):
        read_yaml(broken)
    listing = tmp_path / "list.yaml"
    listing.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must be a mapping of settings, not list"):
        read_yaml(listing)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert read_yaml(empty) == {}
