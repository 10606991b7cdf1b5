"""Every function code through the gateway, byte for byte as the line answers it, with the
client's transaction id and unit id; broadcasts; unit 255; pipelining."""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.pdu import RawPDU, ReadInputRegistersResponse
from aiortu.core.rtu import FrameReceived, Role, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.gateway import gateway
from aiortu.gateway._forward import request_of
from aiortu.line import Link
from aiortu.master import Master
from aiortu.slave import RequestContext
from aiortu.testing import VirtualBus
from tests.gateway.helpers import UNIT, client, line, memory_client
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)

# One request of every public function code the slave serves on a serial line.
REQUESTS = [
    "01 0000 000A",  # read coils
    "02 0000 0008",  # read discrete inputs
    "03 0000 0003",  # read holding registers
    "04 0000 0003",  # read input registers
    "05 0002 FF00",  # write single coil
    "06 0005 BEEF",  # write single register
    "0F 0004 0003 01 05",  # write multiple coils
    "10 0006 0002 04 0001 0002",  # write multiple registers
    "16 0005 FF00 0011",  # mask write register
    "17 0000 0002 0008 0001 02 00AA",  # read/write multiple registers
    "18 04DE",  # read FIFO queue
    "14 07 06 0004 0000 0002",  # read file record
    "15 09 06 0004 0001 0001 1234",  # write file record
    "2B 0E 01 00",  # read device identification
    "07",  # read exception status
    "08 0000 A537",  # diagnostics: return query data
    "0B",  # get comm event counter
    "11",  # report server id
]


def _custom(request: object, context: RequestContext) -> RawPDU:
    assert isinstance(request, RawPDU)
    return RawPDU(0x41, request.data[::-1])


@pytest.mark.parametrize("pdu_hex", REQUESTS, ids=lambda text: f"fc{text[:2]}")
async def test_each_function_code_is_answered_as_the_line_answers_it(pdu_hex: str) -> None:
    async with line() as bench, client(bench.gateway) as tcp:
        pdu = bytes.fromhex(pdu_hex)
        through = await tcp.request(pdu_hex, UNIT, transaction_id=0x1234)
        # The same request sent by the master itself gets the same reply (the requests
        # above leave the device as they found it when sent twice).
        direct = (await bench.master.execute(UNIT, request_of(pdu))).encode()
        assert through == direct.hex(" ").upper()
        assert not bytes.fromhex(through)[0] & 0x80, f"exception reply {through}"


async def test_a_user_defined_code_goes_through_byte_for_byte() -> None:
    async with line() as bench, client(bench.gateway) as tcp:
        bench.slave.set_handler(0x41, _custom)
        assert await tcp.request("41 01 02 03", UNIT, transaction_id=7) == "41 03 02 01"


async def test_a_request_outside_the_spec_is_forwarded_and_the_device_answers() -> None:
    async with line() as bench, client(bench.gateway) as tcp:
        # 0 registers: no request class accepts it, the device answers exception 03.
        assert await tcp.request("03 0000 0000", UNIT) == "83 03"
        assert bench.messages == 1
        # Not requests at all: refused by the gateway, nothing sent.
        assert await tcp.request("00 01", UNIT) == "80 01"
        assert await tcp.request("83 02", UNIT) == "83 01"
        assert bench.messages == 1


async def test_ids_are_the_clients_own_and_pipelined_requests_all_answered() -> None:
    async with line(max_in_flight=4) as bench, client(bench.gateway) as tcp:
        ids = [0xFFFF, 0, 0x8001, 42, 43, 44, 45, 46]
        for transaction_id in ids:
            await tcp.send(f"03 {transaction_id % 3:04X} 0001", UNIT, transaction_id)
        replies = [await tcp.receive() for _ in ids]
        assert sorted(r.transaction_id for r in replies if r) == sorted(ids)
        for reply in replies:
            assert reply is not None
            assert reply.unit == UNIT
            expected = [0x1234, 0xABCD, 7][reply.transaction_id % 3]
            assert reply.pdu == bytes.fromhex(f"03 02 {expected:04X}")


@on_virtual_clock
async def test_broadcast_is_executed_and_not_answered() -> None:
    async with line(listen=()) as bench, memory_client(bench.gateway) as tcp:
        await tcp.send("06 0008 0077", unit=0, transaction_id=5)
        assert await tcp.receive(wait=10) is None
        assert bench.gateway.counters.broadcasts == 1
        assert await tcp.request("03 0008 0001", UNIT) == "03 02 00 77"


async def test_unit_255_is_the_default_unit_or_refused_with_0b() -> None:
    async with line(default_unit=UNIT) as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0000 0001", 0xFF, transaction_id=3) == "03 02 12 34"
    async with line() as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0000 0001", 0xFF, transaction_id=3) == "83 0B"
        assert await tcp.request("03 0000 0001", 250) == "83 0B"
        assert bench.messages == 0


async def _silent_then_misshapen(link: Link) -> None:
    """A device that lets a request outside the spec time out, then answers the next request
    (a read of one input register) twice: first with two registers, then as it should."""
    with anyio.fail_after(10):
        for replies in ([], [ReadInputRegistersResponse((1, 2)), ReadInputRegistersResponse((7,))]):
            event = await link.receive()
            while not isinstance(event, FrameReceived):
                event = await link.receive()
            for reply in replies:
                await link.send(encode_frame(event.unit, reply.encode()))
                await anyio.sleep(0.01)


async def test_a_reply_of_another_code_is_no_late_reply_to_a_request_forwarded_as_it_came() -> None:
    # The read of 0 registers goes out as it came, and times out. The next request's
    # misshapen reply (function code 04) cannot be its late reply (03): the attempt fails
    # at once, and the good reply after it is not taken.
    bus = VirtualBus(2)
    settings = LineSettings(1_000_000)
    device = Link(bus.endpoints[1], settings, role=Role.SLAVE, units=range(248), frame_gap=0)
    master = Master(bus.endpoints[0], settings, frame_gap=0, timeout=0.2, retries=0)
    async with device, master, anyio.create_task_group() as tasks:
        tasks.start_soon(_silent_then_misshapen, device)
        await anyio.sleep(0.05)  # both receivers past their first silence
        async with gateway(master, ["tcp://127.0.0.1:0"]) as server, client(server) as tcp:
            assert await tcp.request("03 0000 0000", UNIT) == "83 0B"
            assert await tcp.request("04 0000 0001", UNIT) == "84 0B"
        assert master.unit_stats(UNIT).late_replies == 0
