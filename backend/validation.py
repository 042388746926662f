"""Bounds of request input, checked at the edge before a handler or the database sees it.

Every id, index, version and counter fits a 32-bit signed integer (PostgreSQL's INTEGER; SQLite
holds it too), every float is finite and bounded, and no string holds a NUL character (PostgreSQL
text cannot store one). A value outside these bounds is a 422 naming its field, like any other
validation error. NUL is refused for every request in one place,
``backend.middleware.RequestGuardMiddleware``: in the path and query string before routing, and
anywhere in a JSON or form body before the handler parses it.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Path, Query
from pydantic import Field, StrictBool

MAX_INT32 = 2**31 - 1
MIN_INT32 = -(2**31)
# Coordinates, weights and every other float the API takes: far beyond any image, scene or
# setting, and small enough that arithmetic on them stays finite.
MAX_ABS_FLOAT = 1e12
# Serials, marketplace ids (MTurk allows 64 characters) and other names in a path.
MAX_KEY_LENGTH = 128

NUL = "\x00"
NUL_MESSAGE = "must not contain a NUL character (\\u0000)"
NUMBER_MESSAGE = (f"numbers must be finite, integers within {MIN_INT32}..{MAX_INT32} and "
                  f"other numbers at most {MAX_ABS_FLOAT:g} in magnitude")


def nul_fields(value: Any, path: tuple[str, ...] = ()) -> list[str]:
    """Where a string in parsed JSON holds a NUL: ``tracks.0.name`` style, keys included."""
    if isinstance(value, str):
        return [".".join(path) or "body"] if NUL in value else []
    found: list[str] = []
    if isinstance(value, dict):
        for key, item in value.items():
            name = str(key).replace(NUL, "?")
            if NUL in str(key):
                found.append(".".join((*path, name)))
            found += nul_fields(item, (*path, name))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += nul_fields(item, (*path, str(index)))
    return found


# ----- path and query parameters ---------------------------------------------------------

# A row id in a path: 1 up to the largest 32-bit integer.
Id = Annotated[int, Path(ge=1, le=MAX_INT32)]
# A frame or object index in a path.
Index = Annotated[int, Path(ge=0, le=MAX_INT32)]
# A serial, marketplace id or other name in a path (NUL is refused before routing).
Key = Annotated[str, Path(min_length=1, max_length=MAX_KEY_LENGTH)]
# An optional id filter in a query string.
QueryId = Annotated[int | None, Query(ge=1, le=MAX_INT32)]
# An optional name filter in a query string.
QueryKey = Annotated[str | None, Query(min_length=1, max_length=MAX_KEY_LENGTH)]
# Where a page of a listing starts.
Offset = Annotated[int, Query(ge=0, le=MAX_INT32)]

# ----- body fields -----------------------------------------------------------------------

BodyId = Annotated[int, Field(ge=1, le=MAX_INT32)]
Int32 = Annotated[int, Field(ge=MIN_INT32, le=MAX_INT32)]
Count = Annotated[int, Field(ge=0, le=MAX_INT32)]
Finite = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_ABS_FLOAT, le=MAX_ABS_FLOAT)]
# A JSON scalar of a track or setting: a boolean, a bounded integer or a bounded finite float.
Scalar = StrictBool | Int32 | Finite
