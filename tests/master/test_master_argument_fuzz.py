"""Every public method of the master and of a unit handle, called with arguments of any
type: each call succeeds or raises a ModbusError with a one-line message, and the master
still answers a valid read afterwards."""

from __future__ import annotations

import contextlib
import inspect
import math
from collections.abc import Callable
from typing import Any

import anyio
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.pdu import RawPDU, ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue, ModbusError, ResponseTimeout
from aiortu.master import BroadcastHandle, Master, UnitHandle
from aiortu.slave import Block, MemoryStore, Slave
from aiortu.testing import VirtualBus

UNIT = 17

ANY = st.one_of(
    st.integers(-(2**70), 2**70),
    st.integers(-2, 300),
    st.floats(allow_nan=True, allow_infinity=True),
    st.just(math.nan),
    st.booleans(),
    st.text(max_size=6),
    st.binary(max_size=6),
    st.none(),
    st.lists(st.one_of(st.integers(-2, 70_000), st.booleans(), st.floats()), max_size=4),
    st.tuples(st.integers(-1, 3), st.integers(-1, 3), st.integers(-1, 3)),
    st.sampled_from([RawPDU(0x41, b"\x01"), ReadHoldingRegistersRequest(0, 2), object()]),
    st.sampled_from([ReadHoldingRegistersResponse, int, "holding", "ABCD", "float32"]),
)
"""Arguments of every type: out-of-range ints, floats, NaN, bools, text, bytes, None, ..."""

VALID: dict[str, st.SearchStrategy[Any]] = {
    "unit": st.just(UNIT),
    "address": st.integers(0, 10),
    "read_address": st.integers(0, 10),
    "write_address": st.integers(0, 10),
    "count": st.integers(1, 4),
    "read_count": st.integers(1, 4),
    "register_count": st.integers(1, 4),
    "value": st.integers(0, 1),
    "values": st.lists(st.integers(0, 1), min_size=1, max_size=3),
    "timeout": st.just(0.05),
    "priority": st.integers(-3, 3),
}
"""Values that make a call go out, for the arguments that have them: a mix of valid and
invalid arguments reaches the checks deeper in."""


def public_methods(cls: type) -> list[str]:
    return sorted(
        name
        for name, member in inspect.getmembers(cls)
        if not name.startswith("_") and inspect.iscoroutinefunction(member)
    ) + sorted(
        name
        for name in ("slave", "unit_stats", "is_online")
        if hasattr(cls, name) and not name.startswith("_")
    )


TARGETS: dict[str, type] = {
    "master": Master,
    "handle": UnitHandle,
    "broadcast": BroadcastHandle,
}
METHODS = {on: public_methods(cls) for on, cls in TARGETS.items()}


def short(value: object) -> bool:
    """Whether a call with this ``timeout=`` ends soon: no number of seconds above 0.1."""
    return not (
        isinstance(value, int | float) and not isinstance(value, bool) and 0.1 < value < math.inf
    )


def argument(name: str) -> st.SearchStrategy[Any]:
    any_value = ANY.filter(short) if name == "timeout" else ANY
    valid = VALID.get(name)
    return any_value if valid is None else st.one_of(valid, valid, any_value)


@st.composite
def calls(draw: st.DrawFn) -> tuple[str, str, list[Any], dict[str, Any]]:
    """A method of the master or of a handle, and arguments for it."""
    on = draw(st.sampled_from(sorted(TARGETS)))
    name = draw(st.sampled_from(METHODS[on]))
    method = getattr(TARGETS[on], name)
    args: list[Any] = []
    kwargs: dict[str, Any] = {}
    for parameter in list(inspect.signature(method).parameters.values())[1:]:
        if parameter.kind is parameter.KEYWORD_ONLY:
            if draw(st.booleans()):
                kwargs[parameter.name] = draw(argument(parameter.name))
        elif parameter.default is parameter.empty or draw(st.booleans()):
            args.append(draw(argument(parameter.name)))
        else:
            break
    return on, name, args, kwargs


def check_error(error: ModbusError) -> None:
    message = str(error)
    assert message, f"{type(error).__name__} without a message"
    assert "\n" not in message, message
    assert " at 0x" not in message, message  # no object's repr
    assert len(message) < 400, message
    if isinstance(error, InvalidValue):
        # It names the argument first: "count = 0 is outside the allowed range 1..125"
        # for a range, "priority must be an int, not 'x'" for anything else.
        assert message.startswith(f"{error.field} "), message
        if not isinstance(error.allowed, range):
            assert "outside the allowed range" not in message, message


async def exercise(sequence: list[tuple[str, str, list[Any], dict[str, Any]]]) -> None:
    bus = VirtualBus(2)
    store = MemoryStore(coils=[Block(0, 16)], holding_registers=[Block(0, 16, list(range(16)))])
    slave = Slave(bus.endpoints[1], {UNIT: store}, frame_gap=0.0, frame_silence=0.005)
    async with (
        slave,
        Master(
            bus.endpoints[0],
            LineSettings(1_000_000),
            frame_gap=0,
            timeout=0.05,
            retries=0,
            turnaround_delay=0.005,
            late_reply_guard=0.005,
        ) as master,
    ):
        await anyio.sleep(0.02)  # both receivers past their first silence
        handle = master.slave(UNIT)
        targets = {"master": master, "handle": handle, "broadcast": master.broadcast}
        for on, name, args, kwargs in sequence:
            method: Callable[..., Any] = getattr(targets[on], name)
            try:
                with anyio.fail_after(5):
                    result = method(*args, **kwargs)
                    if inspect.isawaitable(result):
                        await result
            except ModbusError as error:
                check_error(error)
        # A call may have forced the slave into listen-only mode (08/04): restart its
        # communications (answered unless it was listening only).
        with contextlib.suppress(ResponseTimeout):
            await master.diagnostics(UNIT, 1, timeout=0.5)
        # The calls may have written anything: the reads must succeed, whatever they hold.
        registers = await master.read_holding_registers(UNIT, 14, 2, timeout=2)
        assert len(registers) == 2
        assert len(await handle.read_coils(0, 2, timeout=2)) == 2


@settings(max_examples=80)
@given(st.lists(calls(), min_size=1, max_size=4))
def test_any_arguments_give_a_result_or_a_modbus_error(
    sequence: list[tuple[str, str, list[Any], dict[str, Any]]],
) -> None:
    anyio.run(exercise, sequence)


def test_every_public_method_is_exercised() -> None:
    assert {"read_holding_registers", "execute", "request", "send_without_reply"} <= set(
        METHODS["master"]
    )
    assert {"read_float32", "read_reference", "write_string"} <= set(METHODS["handle"])
    assert {"write_coil", "write_file_record"} <= set(METHODS["broadcast"])
