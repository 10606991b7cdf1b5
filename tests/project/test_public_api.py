"""Every public module declares its public names in ``__all__``, as a tuple, and exports them.

A module is public when no part of its dotted name starts with an underscore. Its
``__all__`` must be a tuple (so it cannot be changed by accident), name only attributes
that exist, hold no duplicates, and list every public class and function defined in the
module itself.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from types import ModuleType

import pytest

import aiortu

# The plugin module is loaded by pytest through its entry point; importing it again
# here is harmless, but the CLI entry module runs nothing at import either.
ALL_MODULES = [info.name for info in pkgutil.walk_packages(aiortu.__path__, prefix="aiortu.")]


PUBLIC_MODULES = sorted(
    name for name in ALL_MODULES if not any(part.startswith("_") for part in name.split("."))
)


def _defined_here(module: ModuleType) -> set[str]:
    names = set()
    for name, value in vars(module).items():
        if name.startswith("_"):
            continue
        if (
            inspect.isclass(value) or inspect.isfunction(value)
        ) and value.__module__ == module.__name__:
            names.add(name)
    return names


def test_there_are_public_modules() -> None:
    assert "aiortu.core.pdu" in PUBLIC_MODULES
    assert "aiortu.errors" in PUBLIC_MODULES


@pytest.mark.parametrize("module_name", ["aiortu", *PUBLIC_MODULES])
def test_all_is_a_tuple_matching_the_exports(module_name: str) -> None:
    module = importlib.import_module(module_name)
    exported = getattr(module, "__all__", None)
    assert isinstance(exported, tuple), f"{module_name}.__all__ must be a tuple"
    assert len(set(exported)) == len(exported), f"{module_name}.__all__ has duplicates"
    missing = [name for name in exported if not hasattr(module, name)]
    assert not missing, f"{module_name}.__all__ names what it does not define: {missing}"
    unlisted = _defined_here(module) - set(exported)
    assert not unlisted, (
        f"{module_name} defines public names missing from __all__: {sorted(unlisted)}"
    )
