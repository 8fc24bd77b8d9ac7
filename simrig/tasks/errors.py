"""A task file's validation errors as one line each: the file, the field as written in the file, what is wrong
and what is allowed (``pilworld task check`` prints them; every other command raises on the first).

Pydantic's own wording is kept where it already says what is allowed ("must be greater than 0"), with three
changes: the shape or fixture kind pydantic puts into a field's path is dropped (``objects.0.size``, not
``objects.0.box.size``); an unknown key names the keys allowed there and the nearest one (a typo); an
unknown ``shape`` or ``kind`` lists the known ones. Unknown keys are listed first: a misspelt required key
also shows up as that key missing, and the typo is what the author has to fix.
"""

from __future__ import annotations

import difflib
import types
import typing
from typing import Any

from pydantic import BaseModel, ValidationError

from simrig.tasks import schema as s

_TAGS = {"shape": s.SHAPES, "kind": ("outline", "ring", "patch", "peg", "block")}
_ORDER = {"extra_forbidden": 0, "union_tag_invalid": 1}


def _unwrap(tp: Any) -> Any:
    """``tp`` without ``Annotated``, ``X | None`` and forward references."""
    while True:
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            tp = typing.get_args(tp)[0]
        elif origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            if len(args) != 1:
                return tp
            tp = args[0]
        elif isinstance(tp, str):
            return getattr(s, tp, None)
        else:
            return tp


def _members(tp: Any) -> list[Any]:
    tp = _unwrap(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return [_unwrap(a) for a in typing.get_args(tp) if a is not type(None)]
    return [tp]


def _step(tp: Any, part: str | int) -> Any:
    """The type one step down ``part`` (a field name, a list index or a union's tag) from ``tp``."""
    members = _members(tp)
    if isinstance(part, str):
        for m in members:  # a union's tag: the member whose shape/kind literal is ``part``
            if isinstance(m, type) and issubclass(m, BaseModel):
                for key in _TAGS:
                    field = m.model_fields.get(key)
                    if field is not None and part in typing.get_args(field.annotation):
                        return m
        for m in members:
            if isinstance(m, type) and issubclass(m, BaseModel) and part in m.model_fields:
                return m.model_fields[part].annotation
        return None
    for m in members:
        if typing.get_origin(m) in (list, tuple):
            args = [a for a in typing.get_args(m) if a is not Ellipsis]
            return args[min(part, len(args) - 1)] if args else None
    return None


def allowed_keys(loc: tuple[str | int, ...]) -> list[str]:
    """The keys allowed in the mapping at ``loc`` (a pydantic error location, union tags included)."""
    tp: Any = s.TaskFile
    for part in loc:
        tp = _step(tp, part)
        if tp is None:
            return []
    members = [m for m in _members(tp) if isinstance(m, type) and issubclass(m, BaseModel)]
    if len(members) != 1:
        return []
    keys = list(members[0].model_fields)
    return [k for k in ("name", "shape", "kind") if k in keys] + [k for k in keys if k not in ("name", "shape", "kind")]


def _field(loc: tuple[str | int, ...]) -> str:
    """``loc`` as the author wrote it: without the union tags pydantic inserts after a list index."""
    out: list[str] = []
    for k, part in enumerate(loc):
        is_tag = (
            k >= 2
            and isinstance(loc[k - 1], int)
            and loc[k - 2] in ("objects", "fixtures")
            and any(part in tags for tags in _TAGS.values())
        )
        if not is_tag:
            out.append(str(part))
    return ".".join(out) or "<root>"


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _line(err: Any) -> tuple[str, str]:
    """(field, message) of one pydantic error."""
    loc = tuple(err["loc"])
    kind = err["type"]
    value = err.get("input")
    ctx = err.get("ctx") or {}
    if kind == "extra_forbidden":
        key = str(loc[-1])
        allowed = allowed_keys(loc[:-1])
        near = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        where = f" (allowed here: {', '.join(allowed)})" if allowed else ""
        return _field(loc), f"unknown key {key!r}{where}{hint}"
    if kind == "union_tag_invalid":
        key = str(ctx.get("discriminator", "")).strip("'")
        known = ", ".join(_TAGS.get(key, ()))
        return _field((*loc, key)), f"unknown {key} {ctx.get('tag')!r} (allowed: {known})"
    if kind == "union_tag_not_found":
        key = str(ctx.get("discriminator", "")).strip("'")
        known = ", ".join(_TAGS.get(key, ()))
        return _field((*loc, key)), f"missing '{key}' (one of: {known})"
    if kind == "missing":
        return _field(loc), "required, but missing"
    message = str(err["msg"]).removeprefix("Value error, ").replace("Input should be", "must be")
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        message = f"must be a mapping (key: value), got {type(value).__name__}"
    shown = _shown(value)
    # The task's own checks (value errors) often name the value already; pydantic's constraints never do.
    if kind != "value_error" or str(value) not in message:
        message += f" (got {shown})"
    return _field(loc), message


def validation_lines(source: str, err: ValidationError) -> list[str]:
    """One line per problem, ``source: field 'a.b': message``; unknown keys first."""
    errors = sorted(err.errors(), key=lambda e: _ORDER.get(e["type"], 2))
    lines = []
    for e in errors:
        field, message = _line(e)
        lines.append(f"{source}: field '{field}': {message}")
    return lines
