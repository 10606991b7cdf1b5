"""No handler, hook or callback can kill the slave.

What a handler or hook returns is checked where the slave takes it: a Response, an
ExceptionPDU, a Reply or None is an answer; anything else gets exception 04, is logged
once for that handler or hook, and never reaches the wire. A trace callback or a store
observer that raises is logged and detached. Every time, the slave goes on serving.
"""

from __future__ import annotations

import logging
from typing import Any

import anyio
import anyio.lowlevel
import pytest

from aiortu.core.pdu import ExceptionPDU, RawPDU
from aiortu.slave import Change, MemoryStore, Reply, Table

from .helpers import UNIT, example_store, raising_trace, slave_line

OTHER_UNIT = 18


def _units() -> dict[int, Any]:
    return {UNIT: example_store(), OTHER_UNIT: MemoryStore(holding_registers={0: [42]})}


def _logged(caplog: pytest.LogCaptureFixture, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


async def test_a_handler_returning_a_number_gets_04_logged_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with slave_line(_units()) as (master, slave):
        slave.set_handler(0x41, lambda request, context: 12345)
        assert await master.request(UNIT, "41 01") == "C1 04"
        assert await master.request(UNIT, "41 02") == "C1 04"
        # The slave serves on, every unit.
        assert await master.request(OTHER_UNIT, "03 00 00 00 01") == "03 02 00 2A"
        assert await master.request(UNIT, "03 00 6B 00 01") == "03 02 AE 41"
    assert slave.counters.bus_exception_error_count == 2
    messages = _logged(caplog, "returned 12345 (an int), not a response")
    assert len(messages) == 1, messages
    assert "function 0x41" in messages[0]
    assert "exception 04" in messages[0]


async def test_a_str_never_reaches_the_wire(caplog: pytest.LogCaptureFixture) -> None:
    sent: list[bytes] = []
    async with slave_line(_units(), trace=lambda kind, data: sent.append(data)) as (master, slave):
        slave.set_handler(0x42, lambda request, context: "\x42hello")
        assert await master.request(UNIT, "42") == "C2 04"
        assert await master.request(OTHER_UNIT, "03 00 00 00 01") == "03 02 00 2A"
    assert not any(b"hello" in data for data in sent)
    assert _logged(caplog, "returned a str")


async def test_a_before_hook_returning_7_gets_04_until_removed(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with slave_line(_units()) as (master, slave):
        remove = slave.before_request(lambda request, context: 7)
        assert await master.request(UNIT, "03 00 6B 00 01") == "83 04"
        assert await master.request(OTHER_UNIT, "06 00 00 00 05") == "86 04"
        remove()
        assert await master.request(OTHER_UNIT, "03 00 00 00 01") == "03 02 00 2A"
    assert len(_logged(caplog, "returned 7 (an int), not a response")) == 1


async def test_an_after_hook_and_an_async_handler_are_checked_too(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def handler(request: object, context: object) -> object:
        await anyio.lowlevel.checkpoint()
        return [1, 2]

    async with slave_line(_units()) as (master, slave):
        slave.set_handler(0x43, handler)
        assert await master.request(UNIT, "43") == "C3 04"
        slave.after_request(lambda request, context, result: b"\x03\x02\x00\x01")
        assert await master.request(UNIT, "03 00 6B 00 01") == "83 04"
    assert _logged(caplog, "returned a list")
    assert _logged(caplog, "returned a bytes")


async def test_exception_pdus_and_replies_are_answers() -> None:
    async with slave_line(_units()) as (master, slave):
        slave.set_handler(0x44, lambda request, context: ExceptionPDU(0x44, 0x06))
        slave.set_handler(0x45, lambda request, context: Reply(RawPDU(0x45, b"\x01")))
        slave.set_handler(0x46, lambda request, context: Reply(RawPDU(0x46), delay=-1.0))
        slave.set_handler(0x47, lambda request, context: Reply(RawPDU(0x47), unit=300))
        slave.set_handler(0x48, lambda request, context: Reply(RawPDU(0x48), delay=-0.001))
        slave.set_handler(0x49, lambda request, context: Reply(RawPDU(0x49), unit=-1))
        assert await master.request(UNIT, "44") == "C4 06"
        assert slave.counters.server_busy_count == 1  # counted as the exception it is
        assert await master.request(UNIT, "45") == "45 01"
        assert await master.request(UNIT, "46") == "C6 04"
        assert await master.request(UNIT, "47") == "C7 04"
        assert await master.request(UNIT, "48") == "C8 04"  # no delay is below 0
        assert await master.request(UNIT, "49") == "C9 04"  # nor a unit id
        assert await master.request(UNIT, "03 00 6B 00 01") == "03 02 AE 41"


async def test_a_raising_trace_callback_is_logged_and_detached(
    caplog: pytest.LogCaptureFixture,
) -> None:
    calls: list[str] = []
    async with slave_line(_units(), trace=raising_trace(calls)) as (master, slave):
        assert await master.request(UNIT, "03 00 6B 00 01") == "03 02 AE 41"
        assert slave.trace is None
        assert await master.request(OTHER_UNIT, "03 00 00 00 01") == "03 02 00 2A"
    assert calls == ["received"]
    assert _logged(caplog, "trace callback failed")


async def test_a_raising_store_observer_is_logged_and_detached(
    caplog: pytest.LogCaptureFixture,
) -> None:
    store = example_store()
    calls: list[Change] = []
    kept: list[Change] = []

    def observer(change: Change) -> None:
        calls.append(change)
        raise RuntimeError("observer broke")

    store.observe(observer)
    store.observe(kept.append)
    caplog.set_level(logging.ERROR)  # before the failure: a level set after sees nothing
    async with slave_line({UNIT: store}) as (master, _):
        assert await master.request(UNIT, "06 00 01 00 07") == "06 00 01 00 07"
        assert await master.request(UNIT, "06 00 02 00 08") == "06 00 02 00 08"
    assert len(calls) == 1
    assert [change.address for change in kept] == [1, 2]
    assert store.get(Table.HOLDING_REGISTERS, 1, 2) == [7, 8]
    assert len(_logged(caplog, "observer failed")) == 1


class _Broken(RawPDU):
    """A response whose encoding fails, as a user's Response subclass might."""

    def encode(self) -> bytes:
        raise RuntimeError("cannot encode")


async def test_a_response_that_fails_to_encode_gets_04(caplog: pytest.LogCaptureFixture) -> None:
    async with slave_line(_units()) as (master, slave):
        slave.set_handler(0x48, lambda request, context: _Broken(0x48))
        slave.set_handler(0x49, lambda request, context: Reply(_Broken(0x49), delay=0.01))
        assert await master.request(UNIT, "48") == "C8 04"
        assert await master.request(UNIT, "49") == "C9 04"
        assert await master.request(OTHER_UNIT, "03 00 00 00 01") == "03 02 00 2A"
    assert len(_logged(caplog, "the handler of function")) == 2
