"""The fast paths for the built-in MemoryStore answer exactly as the handlers do."""

from __future__ import annotations

import random

from aiortu.core.codes import FunctionCode
from aiortu.slave import Block, MemoryStore, Table
from aiortu.slave._answer_at_once import FAST_PATHS

from .helpers import UNIT, slave_line


def _store() -> MemoryStore:
    return MemoryStore(
        coils=[Block(0, 40, [1, 0, 1, 1, 0, 0, 1] * 5), Block(100, 3000)],
        discrete_inputs=Block(10, 20, [1] * 20),
        holding_registers=[Block(0, 100, range(100)), Block(200, 10)],
        input_registers=Table.HOLDING_REGISTERS,
        read_only={Table.HOLDING_REGISTERS: [range(50, 60)]},
    )


def _requests(rng: random.Random) -> list[bytes]:
    """Well-formed requests, and ones wrong in each way a fast path checks."""
    found = []
    for code in FAST_PATHS:
        for _ in range(40):
            address = rng.choice((0, 1, 5, 45, 95, 99, 150, 200, 205, 0xFFF0, 0xFFFF))
            count = rng.choice((0, 1, 3, 10, 100, 123, 124, 125, 126, 2000, 2001, 0x7FFF))
            if code in (FunctionCode.WRITE_SINGLE_REGISTER,):
                pdu = bytes((code,)) + address.to_bytes(2, "big") + rng.randbytes(2)
            elif code == FunctionCode.WRITE_MULTIPLE_REGISTERS:
                values = rng.randbytes(2 * min(count, 125))
                byte_count = rng.choice((len(values), len(values) + 2, (len(values) - 2) % 256))
                pdu = (
                    bytes((code,))
                    + address.to_bytes(2, "big")
                    + count.to_bytes(2, "big")
                    + bytes((byte_count % 256,))
                    + values
                )
            else:
                pdu = bytes((code,)) + address.to_bytes(2, "big") + count.to_bytes(2, "big")
            cut = rng.random()
            if cut < 0.05:
                pdu = pdu[:-1]
            elif cut < 0.1:
                pdu += b"\x00"
            found.append(pdu[:253])
    rng.shuffle(found)
    return found


async def test_fast_paths_answer_as_the_handlers_do() -> None:
    fast_store = _store()
    slow_store = _store()
    # A store value the application put out of range: the handler answers 04.
    fast_store.blocks(Table.HOLDING_REGISTERS)[1].values[3] = 0x10000
    slow_store.blocks(Table.HOLDING_REGISTERS)[1].values[3] = 0x10000
    changes: dict[str, list[object]] = {"fast": [], "slow": []}
    fast_store.observe(changes["fast"].append)
    slow_store.observe(changes["slow"].append)
    requests = _requests(random.Random(20261123))
    requests.append(bytes.fromhex("03 00 C8 00 05"))  # reads the bad value
    async with (
        slave_line({UNIT: fast_store}) as (fast, fast_slave),
        slave_line({UNIT: slow_store}) as (slow, slow_slave),
    ):
        slow_slave.before_request(lambda request, context: None)  # no fast path with a hook
        assert fast_slave._at_once.may_answer(UNIT, 0x03)
        for pdu in requests:
            expected = await slow.request(UNIT, pdu.hex())
            assert await fast.request(UNIT, pdu.hex()) == expected, pdu.hex(" ")
        assert fast_slave.counters == slow_slave.counters
        assert fast_slave.machine.event_log.events() == slow_slave.machine.event_log.events()
    assert changes["fast"] == changes["slow"]
    for table in Table:
        assert [b.values for b in fast_store.blocks(table)] == [
            b.values for b in slow_store.blocks(table)
        ]


def test_fast_paths_reach_the_end_of_the_address_space_and_the_shortest_write() -> None:
    # Declining would still be answered right (by the general route), but not at once: the
    # fast paths serve every well-formed request up to the last address.
    store = MemoryStore(
        coils=Block(0xFFF8, 8, [1, 0] * 4),
        discrete_inputs=Block(0xFFF8, 8, [0, 1] * 4),
        holding_registers=Block(0xFFF8, 8, range(8)),
    )
    answers = {
        "01 FF F8 00 08": "01 01 55",
        "01 FF FF 00 01": "01 01 00",
        "02 FF F8 00 08": "02 01 AA",
        "02 FF FF 00 01": "02 01 01",
        "03 FF FF 00 01": "03 02 00 07",
        "10 FF FF 00 01 02 12 34": "10 FF FF 00 01",  # one register: the shortest PDU
        "10 FF FE 00 02 04 00 01 00 02": "10 FF FE 00 02",
    }
    for request, expected in answers.items():
        pdu = bytes.fromhex(request)
        reply = FAST_PATHS[pdu[0]][1](store, pdu)
        assert reply is not None, request
        assert reply.hex(" ").upper() == expected, request
    assert store.get(Table.HOLDING_REGISTERS, 0xFFFE, 2) == [1, 2]
