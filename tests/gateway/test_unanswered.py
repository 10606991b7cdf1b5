"""Requests that get no reply by the spec, reads to unit 0, and frames forwarded bit for bit:
each is answered at once, never after the master's timeout. On a virtual clock, over in-memory
streams: "at once" is no time at all."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import anyio
import pytest

from aiortu.core.rtu import encode_frame
from tests.gateway.helpers import UNIT, Line, line, memory_client
from tests.virtual_clock import on_virtual_clock

READ = "03 0000 0002"
# The line's timeout is 5 s here: an answer in no time was not a wait for a reply.
SLOW = {"timeout": 5.0, "retries": 0}


@contextlib.contextmanager
def taking(seconds: float = 0.0) -> Iterator[None]:
    """Assert that the block takes `seconds` of virtual time (none by default)."""
    start = anyio.current_time()
    yield
    assert anyio.current_time() - start == pytest.approx(seconds, abs=1e-9)


def unanswered(bench: Line) -> float:
    """The time a request that gets no reply keeps the line: its frame's wire time (8 bytes),
    then the turnaround delay."""
    return 8 * bench.master.settings.char_time + bench.master.turnaround_delay


@on_virtual_clock
async def test_listen_only_is_answered_at_once_and_known_until_restart() -> None:
    async with line(master_options=SLOW, listen=()) as served:
        async with memory_client(served.gateway) as tcp:
            with taking(unanswered(served)):
                assert (await tcp.request("08 0004 0000")) == "08 00 04 00 00"
            assert served.slave.listen_only
            seen = served.messages
            with taking():
                assert (await tcp.request(READ)) == "83 0B"  # not sent: it would not answer
            assert served.messages == seen
            # Restart communications brings it back, offline or not; no reply comes to it.
            with taking(unanswered(served)):
                assert (await tcp.request("08 0001 0000")) == "08 00 01 00 00"
            assert not served.slave.listen_only
            with anyio.fail_after(1):  # a transaction, well within the timeout
                assert (await tcp.request(READ)).startswith("03 04")
        assert served.master.statistics[UNIT].timeouts == 0


@on_virtual_clock
async def test_a_read_to_unit_0_gets_exception_01_at_once() -> None:
    async with line(master_options=SLOW, listen=()) as served:
        seen = served.messages
        async with memory_client(served.gateway) as tcp:
            with taking():
                assert (await tcp.request(READ, unit=0)) == "83 01"
                assert (await tcp.request("08 0000 1234", unit=0)) == "88 01"
        assert served.messages == seen


@on_virtual_clock
async def test_fc_0f_padding_bits_go_to_the_line_as_sent() -> None:
    # 3 coils, and the 5 padding bits of their byte set: the client's frame, bit for bit.
    pdu = bytes.fromhex("0f 0000 0003 01 fd")
    async with line(listen=()) as served:
        async with memory_client(served.gateway) as tcp:
            assert (await tcp.request(pdu.hex())) == "0F 00 00 00 03"
            await tcp.send(pdu.hex(), unit=0)
            await anyio.sleep(0.1)
        sent = [entry.data for entry in served.bus.trace if entry.sender == 0]
        assert encode_frame(UNIT, pdu) in sent
        assert encode_frame(0, pdu) in sent
