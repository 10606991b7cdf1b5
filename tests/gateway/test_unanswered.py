"""Requests that get no reply by the spec, reads to unit 0, and frames forwarded bit for bit:
each is answered at once, never after the master's timeout."""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.rtu import encode_frame
from tests.gateway.helpers import UNIT, client, line

pytestmark = pytest.mark.anyio

READ = "03 0000 0002"
# The line's timeout is 5 s here: an answer within 1 s was not a wait for a reply.
SLOW = {"timeout": 5.0, "retries": 0}


async def test_listen_only_is_answered_at_once_and_known_until_restart() -> None:
    async with line(master_options=SLOW) as served:
        async with client(served.gateway) as tcp:
            with anyio.fail_after(1):
                assert (await tcp.request("08 0004 0000")) == "08 00 04 00 00"
            assert served.slave.listen_only
            seen = served.messages
            with anyio.fail_after(1):
                assert (await tcp.request(READ)) == "83 0B"  # not sent: it would not answer
            assert served.messages == seen
            # Restart communications brings it back, offline or not; no reply comes to it.
            with anyio.fail_after(1):
                assert (await tcp.request("08 0001 0000")) == "08 00 01 00 00"
            assert not served.slave.listen_only
            with anyio.fail_after(1):
                assert (await tcp.request(READ)).startswith("03 04")
        assert served.master.statistics[UNIT].timeouts == 0


async def test_a_read_to_unit_0_gets_exception_01_at_once() -> None:
    async with line(master_options=SLOW) as served:
        seen = served.messages
        async with client(served.gateway) as tcp:
            with anyio.fail_after(1):
                assert (await tcp.request(READ, unit=0)) == "83 01"
                assert (await tcp.request("08 0000 1234", unit=0)) == "88 01"
        assert served.messages == seen


async def test_fc_0f_padding_bits_go_to_the_line_as_sent() -> None:
    # 3 coils, and the 5 padding bits of their byte set: the client's frame, bit for bit.
    pdu = bytes.fromhex("0f 0000 0003 01 fd")
    async with line() as served:
        async with client(served.gateway) as tcp:
            assert (await tcp.request(pdu.hex())) == "0F 00 00 00 03"
            await tcp.send(pdu.hex(), unit=0)
            await anyio.sleep(0.1)
        sent = [entry.data for entry in served.bus.trace if entry.sender == 0]
        assert encode_frame(UNIT, pdu) in sent
        assert encode_frame(0, pdu) in sent
