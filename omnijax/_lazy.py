"""A package's public names imported when first asked for (PEP 562), so that a command that needs only
one light part (the PTZ emulator: the schema kit of :mod:`omnijax.config`) does not import JAX."""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable, Mapping


def lazy_exports(package: str, table: Mapping[str, tuple[str, ...]]) -> tuple[Callable, Callable, list[str]]:
    """``__getattr__``, ``__dir__`` and ``__all__`` for ``package`` from ``{submodule: names}``: each
    name is imported from its submodule the first time it is read, then kept in the package."""
    where = {name: module for module, names in table.items() for name in names}
    space = importlib.import_module(package).__dict__

    def __getattr__(name: str):
        if name in where:
            value = space[name] = getattr(importlib.import_module(f"{package}.{where[name]}"), name)
            return value
        if importlib.util.find_spec(f"{package}.{name}") is not None:  # a subpackage: `omnijax.world.X`
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(space) | set(where))

    return __getattr__, __dir__, sorted(where)
