"""Forwarding for the modules that moved into packages: each old module warns once, when
it is imported, and hands every name on from the module that now holds it.

Most names are public in a package now, and the warning names that package. A name with
no public home (the master's engine, the built-in handler functions) warns again when it
is used, with what to use instead.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class Internal:
    """A name of an old module that is internal now: where it lives (`module`, under
    `name`, which may differ from the old one) and what users should use `instead`."""

    module: str
    name: str
    instead: str


def forward(
    old: str, home: str, public: str, internal: Mapping[str, Internal] | None = None
) -> Callable[[str], Any]:
    """Warn that `old` is deprecated (once: a module is imported once) and return a
    module `__getattr__` that finds each name in `home`; `public` is the package users
    should import from now. The names in `internal` have no public home: each use of one
    warns with its own advice."""
    _warn(f"{old} is deprecated; import from {public} instead")
    return _getattr(old, home, internal or {}, {})


def forward_internal(
    old: str, home: str, instead: str, renamed: Mapping[str, str] | None = None
) -> Callable[[str], Any]:
    """Like `forward`, for a module none of whose names is public now: the warning says
    so and what to use `instead`. `renamed` maps an old name to its name in `home`."""
    _warn(f"{old} is internal now; {instead}")
    return _getattr(old, home, {}, renamed or {})


def _warn(message: str) -> None:
    # 4: the old module's body, which called forward(), which called this.
    warnings.warn(message, DeprecationWarning, stacklevel=4)


def _getattr(
    old: str, home: str, internal: Mapping[str, Internal], renamed: Mapping[str, str]
) -> Callable[[str], Any]:
    def __getattr__(name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        moved = internal.get(name)
        if moved is None:
            return getattr(importlib.import_module(home), renamed.get(name, name))
        warnings.warn(
            f"{old}.{name} is internal now; {moved.instead}", DeprecationWarning, stacklevel=2
        )
        return getattr(importlib.import_module(moved.module), moved.name)

    return __getattr__
