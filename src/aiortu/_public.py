"""Public names show their public home: `aiortu.Master`, not the private module it is written in.

Each public package calls [`publish`][aiortu._public.publish] at the end of its `__init__`,
so that `repr()`, tracebacks, pickles and `help()` name the import users write.
"""

from __future__ import annotations

import inspect
import pkgutil
import sys
from collections.abc import Iterable, Mapping
from functools import cache
from types import ModuleType


def _home_of(module: str) -> str:
    """The public module that owns *module*: itself, or the package of its first private part."""
    parts = module.split(".")
    for index, part in enumerate(parts):
        if part.startswith("_") and not part.startswith("__"):
            return ".".join(parts[:index])
    return module


def _top() -> ModuleType:
    # Looked up, not imported: the top-level package imports every package for type checks.
    return sys.modules[__package__]


@cache
def _subpackages() -> frozenset[str]:
    # `aiortu.gateway` is the package once imported, so the function `gateway` keeps its own.
    return frozenset(info.name for info in pkgutil.iter_modules(_top().__path__))


def publish(package: str, names: Iterable[str], namespace: Mapping[str, object]) -> None:
    """Set the `__module__` of the classes and functions *package* exports to their public home.

    The home is `aiortu` for the names the top-level package re-exports from here, else
    *package* for what its private modules define. Names defined in another public module
    are left to the package that exports them. A function made by a factory takes the name
    it is exported under, so that it pickles by that name.
    """
    for name in names:
        value = namespace.get(name)  # a name imported on first use is published then
        if not (inspect.isclass(value) or inspect.isfunction(value)):
            continue
        if inspect.isfunction(value) and namespace.get(value.__qualname__) is not value:
            value.__name__ = value.__qualname__ = name  # made by a factory: named as exported
        home = _home_of(value.__module__)
        if _top()._LAZY.get(name) in (package, home) and name not in _subpackages():
            value.__module__ = "aiortu"
        elif home == package:
            value.__module__ = package
