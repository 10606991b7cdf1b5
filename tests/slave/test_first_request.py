"""The first request on an in-memory line, sent right after the slave starts, is answered
even where its length cannot be predicted: a pushing VirtualBus never starts mid-frame,
so the slave's receiver does not wait for a first silence (INIT) and take the request
for the tail of an earlier frame."""

from __future__ import annotations

import anyio

import aiortu
from aiortu.core.pdu import RawPDU
from aiortu.core.rtu import ReceiverState, Role
from aiortu.testing import VirtualBus


async def test_a_custom_request_sent_at_once_after_the_slave_starts_is_answered() -> None:
    bus = VirtualBus(2)
    store = aiortu.MemoryStore(holding_registers={0: [1]})
    slave = aiortu.Slave(bus.endpoints[1], {1: store}, frame_gap=0)
    slave.set_handler(0x41, lambda request, context: RawPDU(0x41, b"\x01"))
    master = aiortu.Master(bus.endpoints[0], frame_gap=0, timeout=2, retries=0)
    async with slave, master:
        with anyio.fail_after(5):
            reply = await master.request(1, RawPDU(0x41, b"\x01\x02"), RawPDU)
    assert reply == RawPDU(0x41, b"\x01")
    assert master.unit_stats(1).retries == 0


async def test_a_link_on_a_serial_like_stream_still_waits_for_silence_first() -> None:
    # The spec's rule where a wire may be mid-frame: the receiver starts in INIT.
    bus = VirtualBus(2, chunk_size=256)  # not pushing: read as a plain stream
    link = aiortu.line.Link(bus.endpoints[1], role=Role.SLAVE, units=(1,))
    async with link:
        assert link.receiver.state is ReceiverState.INIT
