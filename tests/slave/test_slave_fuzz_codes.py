"""Fuzz the serial line, file and identification codes at the slave: random and mutated
frames never crash it, a bad CRC is never answered, and memory stays bounded.

``HYPOTHESIS_PROFILE=long`` runs many more examples (see tests/conftest.py).
"""

from __future__ import annotations

import os
import random
import tracemalloc

import anyio
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.rtu import crc16, decode_frame, encode_frame
from aiortu.slave import MemoryStore, ServerId

from .helpers import UNIT, slave_line

_LONG = os.environ.get("HYPOTHESIS_PROFILE") == "long"
_EXAMPLES = 5_000 if _LONG else 25

_SEEDS = [
    encode_frame(UNIT, bytes.fromhex(pdu))
    for pdu in (
        "08 00 00 A5 37",
        "08 00 0B 00 00",
        "08 00 01 FF 00",
        "0B",
        "0C",
        "11",
        "14 07 06 00 01 00 00 00 02",
        "15 09 06 00 01 00 00 00 01 12 34",
        "2B 0E 03 00",
        "2B 0E 04 80",
        "03 00 00 00 02",
    )
]


def _store() -> MemoryStore:
    return MemoryStore(
        holding_registers={0: 8},
        files={1: 10},
        device_identification={0: "v", 1: "p", 2: "r", 0x80: "x" * 200, 0x81: "y" * 200},
        server_id=ServerId(b"\x01"),
    )


@st.composite
def mutated(draw: st.DrawFn) -> bytes:
    frame = bytearray(draw(st.sampled_from(_SEEDS)))
    for _ in range(draw(st.integers(1, 3))):
        frame[draw(st.integers(0, len(frame) - 1))] ^= draw(st.integers(1, 255))
    if draw(st.booleans()):
        # Keep the CRC right, so that the mutated request reaches the handlers.
        frame = bytearray(encode_frame(UNIT, bytes(frame[1:-2]) or b"\x08"))
    return bytes(frame)


_FRAMES = st.lists(st.one_of(st.binary(min_size=1, max_size=60), mutated()), min_size=1, max_size=4)


@settings(max_examples=_EXAMPLES)
@given(_FRAMES)
def test_fuzzed_serial_line_frames(frames: list[bytes]) -> None:
    async def scenario() -> None:
        async with slave_line({UNIT: _store()}) as (master, slave):
            for frame in frames:
                await master.send(frame)
                await anyio.sleep(0.008)
            await anyio.sleep(0.01)
            if slave.listen_only:
                slave.listen_only = False
            await master.send_request(UNIT, "07")
            answered = 0
            while True:
                reply = await master.receive_frame(wait=1.0)
                assert reply is not None, "the slave stopped answering"
                if decode_frame(reply).pdu[0] == 0x07:
                    break
                answered += 1
            good = sum(len(f) >= 4 and crc16(f) == 0 and f[0] == UNIT for f in frames)
            assert answered <= good
            assert slave.machine.state.name == "IDLE"
            assert len(slave.machine.event_log) <= 64

    anyio.run(scenario)


async def test_memory_stays_bounded_under_a_flood_of_frames() -> None:
    rng = random.Random(7)
    async with slave_line({UNIT: _store()}) as (master, slave):

        async def flood(count: int) -> None:
            for index in range(count):
                if index % 3 == 0:
                    frame = bytearray(rng.choice(_SEEDS))
                    frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)
                    data = bytes(frame)
                else:
                    data = rng.randbytes(rng.randrange(1, 80))
                await master.send(data)
                if index % 20 == 0:
                    await anyio.sleep(0.006)

        await flood(300)
        await anyio.sleep(0.05)
        tracemalloc.start()
        try:
            before = tracemalloc.take_snapshot()
            await flood(1500)
            await anyio.sleep(0.05)
            after = tracemalloc.take_snapshot()
        finally:
            tracemalloc.stop()
        growth = sum(stat.size_diff for stat in after.compare_to(before, "filename"))
        assert growth < 512 * 1024, growth
        slave.listen_only = False
        await anyio.sleep(0.02)
        await master.send_request(UNIT, "07")
        while (reply := await master.receive_frame(wait=1.0)) is not None:
            if decode_frame(reply).pdu[0] == 0x07:
                break
        assert reply is not None
