"""Load YAML files into validated pydantic models, with errors that name the file and the field.

Every config in ``configs/`` goes through :func:`load_yaml_model`, so a typo in a rig file reads
``configs/rig/x.yaml: field 'arms.left.model': unknown arm model 'ur5x' ...`` instead of a traceback.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

M = TypeVar("M", bound=BaseModel)


class ConfigError(ValueError):
    """A config file is missing, unreadable or invalid; the message names the file and the field."""


class StrictModel(BaseModel):
    """Base of every config model: unknown keys are errors (a misspelt key must not be ignored)."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)


def format_validation_error(source: str, err: ValidationError) -> str:
    """One line per problem: ``source: field 'a.b': message (got value)``."""
    lines = []
    for problem in err.errors():
        loc = ".".join(str(part) for part in problem["loc"]) or "<root>"
        message = problem["msg"].removeprefix("Value error, ")
        got = problem.get("input")
        shown = repr(got) if not isinstance(got, dict | list) else type(got).__name__
        if len(shown) > 80:
            shown = shown[:77] + "..."
        lines.append(f"{source}: field '{loc}': {message} (got {shown})")
    return "\n".join(lines)


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping with ``safe_load``; raise :class:`ConfigError` naming the file."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not a text file (byte {err.start} is not UTF-8); expected a YAML config") from None
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {' '.join(str(err).split())}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def validate_model(model: type[M], data: dict[str, Any], *, source: str, context: dict[str, Any] | None = None) -> M:
    """Validate ``data`` as ``model``; raise :class:`ConfigError` naming ``source`` and each bad field."""
    try:
        return model.model_validate(data, context=context)
    except ValidationError as err:
        raise ConfigError(format_validation_error(source, err)) from None


def load_yaml_model(model: type[M], path: str | Path) -> M:
    """Read ``path`` and validate it as ``model``. Relative paths inside the file resolve against its folder."""
    path = Path(path)
    data = read_yaml(path)
    return validate_model(model, data, source=str(path), context={"base_dir": path.resolve().parent})
