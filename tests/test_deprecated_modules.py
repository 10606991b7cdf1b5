"""The modules that moved into packages still import every name they had, and warn once
with the public place each name lives in now.

Before the packages, users imported from flat modules (`aiortu.store`,
`aiortu.master_engine`, ...). `OLD_ALL` freezes each one's `__all__` as it was at 7dbb052,
the last release with the flat layout; every name in it must still import through the
forwarding module that replaced it.
"""

from __future__ import annotations

import importlib
import re
import sys
import warnings
from typing import Any

import pytest

from tests.test_public_api import DEPRECATED_MODULES

OLD_ALL: dict[str, tuple[str, ...]] = {
    "aiortu.link": ("Link", "LinkEvent", "LinkListener"),
    "aiortu.wake_timer": ("WakeTimer", "create_wake_timer"),
    "aiortu.store": (
        "AsyncDataStore", "Block", "Change", "ChangeFeed", "DataStore", "MemoryStore",
        "ServerId", "SupportsDeviceIdentification", "SupportsExceptionStatus",
        "SupportsFifoQueues", "SupportsFileRecords", "SupportsServerId", "Table",
    ),
    "aiortu.master_connection": ("LineConnection", "ReconnectPolicy", "StreamOpener"),
    "aiortu.master_engine": ("HealthPolicy", "LineEngine", "UnitOffline", "UnitStats"),
    "aiortu.master_handles": (
        "BroadcastHandle", "FileRecordLike", "RecordRequestLike", "UnitHandle",
        "as_file_record", "as_record_request",
    ),
    "aiortu.master_job": ("Job", "Reply"),
    "aiortu.master_serial": ("SerialLineFunctions",),
    "aiortu.master_stats": ("HealthPolicy", "UnitStats"),
    "aiortu.poller": (
        "CycleReport", "CycleStats", "Point", "Poller", "Sample", "UnitHealth", "UnitSkipped",
    ),
    "aiortu.slave_config": ("ConfigError", "DeviceConfig", "load_config", "parse_config"),
    "aiortu.slave_handlers": (
        "BUILTIN_HANDLERS", "FAST_PATHS", "FastPath", "Answer", "Handler", "HandlerResult",
        "Reply", "RequestContext", "diagnostics", "get_comm_event_counter",
        "get_comm_event_log", "mask_write_register", "read_coils", "read_device_identification",
        "read_discrete_inputs", "read_exception_status", "read_fifo_queue", "read_file_record",
        "read_holding_registers", "read_input_registers", "read_write_multiple_registers",
        "report_server_id", "write_file_record", "write_multiple_coils",
        "write_multiple_registers", "write_single_coil", "write_single_register",
    ),
    "aiortu.slave_routes": ("RangeAccess", "RangeHandler", "RoutedStore"),
    "aiortu.testing.virtual_bus": ("TraceEntry", "VirtualBus", "VirtualEndpoint", "virtual_pair"),
    "aiortu.testing.pty_bus": ("PtyBus", "make_raw"),
    "aiortu.testing.faults": ("FaultInjector", "FaultPlan", "FaultStats", "FaultedChunk"),
    "aiortu.testing.demo": ("Demo", "DemoEvent", "DeviceView", "ReadingView", "Snapshot"),
    "aiortu.testing.demo_devices": (
        "DigitalIO", "EnergyMeter", "Reading", "SimulatedDevice", "TemperatureController",
        "Value", "from_tenths", "to_tenths",
    ),
}  # fmt: skip
"""Each old module's `__all__` at 7dbb052 (`git show 7dbb052:src/aiortu/store.py`)."""

PUBLIC: dict[str, str] = {
    "aiortu.link": "aiortu.line",
    "aiortu.wake_timer": "aiortu.line",
    "aiortu.store": "aiortu.slave",
    "aiortu.master_connection": "aiortu.master",
    "aiortu.master_engine": "aiortu.master",
    "aiortu.master_handles": "aiortu.master",
    "aiortu.master_stats": "aiortu.master",
    "aiortu.poller": "aiortu.master",
    "aiortu.slave_config": "aiortu.slave",
    "aiortu.slave_handlers": "aiortu.slave",
    "aiortu.slave_routes": "aiortu.slave",
    "aiortu.testing.virtual_bus": "aiortu.testing",
    "aiortu.testing.pty_bus": "aiortu.testing",
    "aiortu.testing.faults": "aiortu.testing",
}
"""The public package that holds the old module's names now (the others are internal)."""

INTERNAL: dict[tuple[str, str], str] = {
    ("aiortu.master_engine", "LineEngine"): "aiortu.master._engine.LineEngine",
    ("aiortu.master_handles", "as_file_record"): "aiortu.master._handles.as_file_record",
    ("aiortu.master_handles", "as_record_request"): "aiortu.master._handles.as_record_request",
    ("aiortu.master_job", "Job"): "aiortu.master._job.Job",
    ("aiortu.master_job", "Reply"): "aiortu.master._job.JobResult",
    ("aiortu.master_serial", "SerialLineFunctions"): (
        "aiortu.master._serial_line.SerialLineFunctions"
    ),
    ("aiortu.slave_handlers", "FAST_PATHS"): "aiortu.slave._answer_at_once.FAST_PATHS",
    ("aiortu.slave_handlers", "FastPath"): "aiortu.slave._answer_at_once.FastPath",
    **{
        ("aiortu.testing.demo", name): f"aiortu.cli._demo_system.{name}"
        for name in OLD_ALL["aiortu.testing.demo"]
    },
    **{
        ("aiortu.testing.demo_devices", name): f"aiortu.cli._demo_devices.{name}"
        for name in OLD_ALL["aiortu.testing.demo_devices"]
    },
}
"""Names with no public home, and where they live now (the slave's built-in handler
functions are added below)."""

_HANDLERS = [name for name in OLD_ALL["aiortu.slave_handlers"] if name.islower()]
INTERNAL.update(
    {("aiortu.slave_handlers", name): f"aiortu.slave._handlers.{name}" for name in _HANDLERS}
)

_PATH = re.compile(r"\baiortu(?:\.\w+)+")

CASES = [(old, name) for old in sorted(OLD_ALL) for name in OLD_ALL[old]]


def _resolve(path: str) -> Any:
    """The object a dotted path names: a module, or an attribute of one (nested too)."""
    parts = path.split(".")
    for split in range(len(parts), 0, -1):
        try:
            value: Any = importlib.import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        for part in parts[split:]:
            value = getattr(value, part)
        return value
    raise AssertionError(f"{path} names nothing")


def _import_fresh(old: str, name: str) -> tuple[object, list[str]]:
    """Import `old` anew, take `name` from it twice and import it again; return the value
    and the messages of the DeprecationWarnings raised meanwhile."""
    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(old)
        value = getattr(module, name)
        assert getattr(module, name) is value
        importlib.import_module(old)
    return value, [str(w.message) for w in caught if w.category is DeprecationWarning]


def test_every_forwarding_module_is_covered() -> None:
    assert sorted(OLD_ALL) == DEPRECATED_MODULES
    assert set(PUBLIC) <= set(OLD_ALL)
    assert all(key in CASES for key in INTERNAL)


@pytest.mark.parametrize(("old", "name"), CASES)
def test_each_old_name_imports_and_the_warning_names_its_public_place(old: str, name: str) -> None:
    value, messages = _import_fresh(old, name)
    public = PUBLIC.get(old)
    if public is None:  # nothing of the module is public: one warning says so
        assert len(messages) == 1, messages
        assert messages[0].startswith(f"{old} is internal now; "), messages
    elif (old, name) in INTERNAL:  # the module's warning, then the name's own at each use
        assert len(messages) == 3, messages
        assert messages[1] == messages[2]
        assert messages[0] == f"{old} is deprecated; import from {public} instead"
        assert messages[1].startswith(f"{old}.{name} is internal now; "), messages
    else:
        assert messages == [f"{old} is deprecated; import from {public} instead"]
        assert value is getattr(importlib.import_module(public), name)
    if (old, name) in INTERNAL:
        assert value is _resolve(INTERNAL[old, name])
    if name in _HANDLERS:
        code = re.fullmatch(r".*BUILTIN_HANDLERS\[aiortu\.FunctionCode\.(\w+)\]", messages[1])
        assert code is not None, messages[1]
        handlers = _resolve("aiortu.slave.BUILTIN_HANDLERS")
        assert value is handlers[_resolve(f"aiortu.FunctionCode.{code[1]}")]
    for path in _PATH.findall(" ".join(messages)):
        if not path.startswith(f"{old}."):  # the old name itself
            assert not any(part.startswith("_") for part in path.split(".")), path
            _resolve(path)  # the place a warning sends users to exists


@pytest.mark.parametrize("old", sorted(OLD_ALL))
def test_an_unknown_name_is_an_attribute_error(old: str) -> None:
    sys.modules.pop(old, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        module = importlib.import_module(old)
    with pytest.raises(AttributeError):
        _ = module.no_such_name_here
