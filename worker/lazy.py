"""Package faces that load some of their names on first use (PEP 562), so that importing a
package for its light names (joint tables, input types) does not import what its heavy names
need (PyTorch, SciPy)."""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from typing import Any


def lazy_names(package: dict[str, Any], where: dict[str, str]) -> Callable[[str], object]:
    """The module ``__getattr__`` of the package whose globals are ``package``: a name of
    ``where`` is imported from the module it maps to when first read, then kept."""

    def __getattr__(name: str) -> object:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package['__name__']!r} has no attribute {name!r}")
        value = getattr(import_module(module), name)
        package[name] = value
        return value

    return __getattr__
