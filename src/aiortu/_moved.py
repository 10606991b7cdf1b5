"""Forwarding for the modules that moved into packages: each old module warns once, when
it is imported, and hands every name on from the module that now holds it."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any


def forward(old: str, home: str, public: str) -> Callable[[str], Any]:
    """Warn that `old` is deprecated (once: a module is imported once) and return a
    module `__getattr__` that finds each name in `home`; `public` is where users
    should import it from now."""
    warnings.warn(
        f"{old} is deprecated; import from {public} instead",
        DeprecationWarning,
        stacklevel=3,
    )

    def __getattr__(name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(importlib.import_module(home), name)

    return __getattr__
