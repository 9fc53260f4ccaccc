"""Bridge settings: YAML → pydantic model, with bad values normalised instead of fatal.

A bridge runs on a robot next to everything else; a typo in its YAML must not stop it. Each
value that fails validation is replaced by the field's default and named in a warning
(``rescan_period_sec=-1.0 is invalid (Input should be greater than 0); using 2.0``). Unknown
keys are warned about and ignored. Only a file that cannot be read or parsed is an error.

A model may define ``prepare_settings(values, warn)`` (a classmethod): it is given the raw
values first and may rewrite them with a warning (the action-status bridge upper-snake-cases
its ``code_prefix``) before they are validated.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from faultledger.errors import ConfigError

M = TypeVar("M", bound=BaseModel)


def normalise(model: type[M], raw: Mapping[str, Any], warn: Callable[[str], None],
              where: str = "") -> M:
    """``model`` validated from ``raw``; invalid or unknown top-level keys fall back to the
    defaults with a warning naming key and value."""
    prefix = f"{where}." if where else ""
    values = dict(raw)
    for key in [k for k in values if k not in model.model_fields]:
        warn(f"{prefix}{key} is not a setting of this bridge; ignored")
        del values[key]
    prepare = getattr(model, "prepare_settings", None)
    if callable(prepare):
        prepare(values, lambda message: warn(f"{prefix}{message}"))
    while True:
        try:
            return model.model_validate(values)
        except ValidationError as error:
            bad = {str(e["loc"][0]): e["msg"] for e in error.errors() if e["loc"]}
            if not bad or not bad.keys() & values.keys():
                raise  # a default itself is invalid: a bug of the model, not of the file
            for key, why in bad.items():
                if key in values:
                    default = model.model_fields[key].get_default(call_default_factory=True)
                    warn(f"{prefix}{key}={values.pop(key)!r} is invalid ({why}); "
                         f"using {default!r}")


def read_yaml(path: Path) -> dict[str, Any]:
    """The mapping in a YAML file (empty file: empty mapping)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"cannot read bridge config {path}: {error.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ConfigError(f"bridge config {path} is not valid YAML: {error}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"bridge config {path} must be a mapping of settings, "
                          f"not {type(data).__name__}")
    return data
