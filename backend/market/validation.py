"""Checking JSON values against botocore's own mturk 2017-01-17 service model.

botocore validates only part of a request on the client (required members, types, minimums);
the service must check the rest: maximum lengths and ranges, enums and the ``pattern`` strings.
The same walk checks our responses against the output shapes, so the marketplace never sends
what a real MTurk could not.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import botocore.session
from botocore.model import (
    ListShape,
    MapShape,
    OperationModel,
    ServiceModel,
    Shape,
    StringShape,
    StructureShape,
)

INT32 = (-(2**31), 2**31 - 1)
INT64 = (-(2**63), 2**63 - 1)
MAX_REPORTED = 10


@lru_cache
def service_model() -> ServiceModel:
    """The mturk service model shipped inside the installed botocore."""
    return botocore.session.get_session().get_service_model("mturk", "2017-01-17")


@lru_cache(maxsize=512)
def _pattern(text: str) -> re.Pattern[str]:
    return re.compile(text)


def operation(name: str) -> OperationModel | None:
    model = service_model()
    return model.operation_model(name) if name in model.operation_names else None


def problems(shape: Shape | None, value: Any, path: str = "") -> list[str]:
    """Every way ``value`` breaks ``shape``; each message names the member path."""
    found: list[str] = []
    if shape is not None:
        _check(shape, value, path, found)
    return found


def describe(found: list[str]) -> str:
    head = f"{len(found)} validation error{'s' if len(found) > 1 else ''} detected: "
    return head + "; ".join(found[:MAX_REPORTED])


def _where(path: str) -> str:
    return path or "the request body"


def _check(shape: Shape, value: Any, path: str, found: list[str]) -> None:
    kind = shape.type_name
    checker = _CHECKERS.get(kind)
    if checker is None:
        found.append(f"{_where(path)}: shape type {kind} is not supported")
        return
    checker(shape, value, path, found)


def _check_structure(shape: StructureShape, value: Any, path: str, found: list[str]) -> None:
    if not isinstance(value, dict):
        found.append(f"{_where(path)} must be an object, got {type(value).__name__}")
        return
    members = shape.members
    found.extend(f"{_join(path, name)} is required"
                 for name in shape.required_members if value.get(name) is None)
    for name, item in value.items():
        member_path = _join(path, name)
        if name not in members:
            found.append(f"{member_path} is not a member of {shape.name}")
        elif item is not None:
            _check(members[name], item, member_path, found)


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _check_list(shape: ListShape, value: Any, path: str, found: list[str]) -> None:
    if not isinstance(value, list):
        found.append(f"{path} must be a list, got {type(value).__name__}")
        return
    _check_size(shape, len(value), path, "items", found)
    for index, item in enumerate(value):
        _check(shape.member, item, f"{path}[{index}]", found)


def _check_map(shape: MapShape, value: Any, path: str, found: list[str]) -> None:
    if not isinstance(value, dict):
        found.append(f"{path} must be an object, got {type(value).__name__}")
        return
    _check_size(shape, len(value), path, "entries", found)
    for key, item in value.items():
        _check(shape.key, key, f"{path} key", found)
        _check(shape.value, item, f"{path}.{key}", found)


def _check_size(shape: Shape, size: int, path: str, unit: str, found: list[str]) -> None:
    low, high = shape.metadata.get("min"), shape.metadata.get("max")
    if low is not None and size < low:
        found.append(f"{path} must have at least {low} {unit}, got {size}")
    if high is not None and size > high:
        found.append(f"{path} must have at most {high} {unit}, got {size}")


def _check_string(shape: StringShape, value: Any, path: str, found: list[str]) -> None:
    if not isinstance(value, str):
        found.append(f"{path} must be a string, got {type(value).__name__}")
        return
    _check_size(shape, len(value), path, "characters", found)
    enum = shape.enum
    if enum and value not in enum:
        found.append(f"{path} {value!r} is not one of {', '.join(enum)}")
    pattern = shape.metadata.get("pattern")
    if pattern and _pattern(pattern).fullmatch(value) is None:
        found.append(f"{path} {_clip(value)!r} does not match the pattern {pattern}")


def _clip(value: str) -> str:
    return value if len(value) <= 80 else value[:77] + "..."


def _check_integer(shape: Shape, value: Any, path: str, found: list[str]) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        found.append(f"{path} must be an integer, got {type(value).__name__}")
        return
    low, high = INT64 if shape.type_name == "long" else INT32
    low = max(low, shape.metadata.get("min", low))
    high = min(high, shape.metadata.get("max", high))
    if not low <= value <= high:
        found.append(f"{path} must be between {low} and {high}, got {value}")


def _check_boolean(shape: Shape, value: Any, path: str, found: list[str]) -> None:
    if not isinstance(value, bool):
        found.append(f"{path} must be true or false, got {type(value).__name__}")


def _check_timestamp(shape: Shape, value: Any, path: str, found: list[str]) -> None:
    # The JSON protocol sends timestamps as seconds since the epoch.
    if isinstance(value, bool) or not isinstance(value, int | float):
        found.append(f"{path} must be a timestamp in epoch seconds, got {type(value).__name__}")
    elif not 0 <= value < 253402300800:  # before year 10000, like every AWS timestamp
        found.append(f"{path} {value} is not a valid timestamp")


def _check_number(shape: Shape, value: Any, path: str, found: list[str]) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        found.append(f"{path} must be a number, got {type(value).__name__}")


# botocore builds a StructureShape for a "structure", a ListShape for a "list", a MapShape for a
# "map" and a StringShape for a "string", so each checker takes the class its type name gets.
_CHECKERS: dict[str, Callable[[Any, Any, str, list[str]], None]] = {
    "structure": _check_structure,
    "list": _check_list,
    "map": _check_map,
    "string": _check_string,
    "integer": _check_integer,
    "long": _check_integer,
    "boolean": _check_boolean,
    "timestamp": _check_timestamp,
    "float": _check_number,
    "double": _check_number,
}
