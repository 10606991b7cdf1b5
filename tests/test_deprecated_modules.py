"""The modules that moved into packages still import, warn once, and hand every name on.

Before the packages, users imported from flat modules (``aiortu.store``,
``aiortu.master_engine``, ...). Each is now a forwarding module: importing it warns once
with a DeprecationWarning that names the new home, and every name it had is still there.
"""

from __future__ import annotations

import importlib
import sys
import warnings

import pytest

from tests.test_public_api import DEPRECATED_MODULES

# A name each old module had, and the public package it now lives in.
MOVED = {
    "aiortu.link": ("Link", "aiortu.line"),
    "aiortu.wake_timer": ("WakeTimer", "aiortu.line"),
    "aiortu.master_serial": ("SerialLineFunctions", "aiortu.master"),
    "aiortu.master_handles": ("UnitHandle", "aiortu.master"),
    "aiortu.master_engine": ("LineEngine", "aiortu.master"),
    "aiortu.master_job": ("Job", "aiortu.master"),
    "aiortu.master_stats": ("UnitStats", "aiortu.master"),
    "aiortu.master_connection": ("ReconnectPolicy", "aiortu.master"),
    "aiortu.poller": ("Poller", "aiortu.master"),
    "aiortu.slave_handlers": ("RequestContext", "aiortu.slave"),
    "aiortu.slave_routes": ("RoutedStore", "aiortu.slave"),
    "aiortu.slave_config": ("load_config", "aiortu.slave"),
    "aiortu.store": ("MemoryStore", "aiortu.slave"),
    "aiortu.testing.virtual_bus": ("VirtualBus", "aiortu.testing"),
    "aiortu.testing.pty_bus": ("PtyBus", "aiortu.testing"),
    "aiortu.testing.faults": ("FaultPlan", "aiortu.testing"),
}


def test_every_forwarding_module_is_covered() -> None:
    assert sorted(MOVED) == DEPRECATED_MODULES


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_module_warns_once_and_forwards(old: str) -> None:
    name, public = MOVED[old]
    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(old)
        value = getattr(module, name)
        getattr(module, name)
        importlib.import_module(old)
    messages = [str(w.message) for w in caught if w.category is DeprecationWarning]
    assert messages == [f"{old} is deprecated; import from {public} instead"]
    assert value is getattr(importlib.import_module(public), name, value)
    with pytest.raises(AttributeError):
        _ = module.no_such_name_here
