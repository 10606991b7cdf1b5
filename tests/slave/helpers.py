"""Helpers for the slave tests: a raw-frame master on a virtual line with a running slave."""

from __future__ import annotations

from collections.abc import AsyncIterator, Mapping
from contextlib import asynccontextmanager
from typing import Any

import anyio

from aiortu.core.model import DataStore
from aiortu.core.rtu import CANNOT_KNOW, decode_frame, encode_frame, expected_response_length
from aiortu.slave import Block, MemoryStore, Slave, TraceCallback
from aiortu.testing import VirtualEndpoint, virtual_pair

__all__ = ("UNIT", "RawMaster", "example_store", "raising_trace", "slave_line")

UNIT = 17
"""The unit the slave under test serves."""


def example_store() -> MemoryStore:
    """A store holding the values of the spec's examples."""
    coils = Block(0x13, 19, _bits(bytes.fromhex("CD 6B 05"), 19))
    inputs = Block(0xC4, 22, _bits(bytes.fromhex("AC DB 35"), 22))
    return MemoryStore(
        coils=[coils, Block(0xAC, 1)],
        discrete_inputs=inputs,
        holding_registers=[
            Block(0x00, 20, [0, 0, 0, 0x00FE, 0x0ACD, 0x0001, 0x0003, 0x000D, 0x00FF] + [0] * 11),
            Block(0x6B, 3, [0xAE41, 0x5652, 0x4340]),
        ],
        input_registers={0x08: [0x000A]},
        fifo_queues={0x04DE: [0x01B8, 0x1284]},
        exception_status=0x6D,
    )


def raising_trace(calls: list[str]) -> TraceCallback:
    """A trace callback that notes in `calls` each kind it is shown, then raises."""

    def trace(kind: str, data: bytes) -> None:
        calls.append(kind)
        raise RuntimeError("trace broke")

    return trace


def _bits(packed: bytes, count: int) -> list[int]:
    return [packed[index // 8] >> (index % 8) & 1 for index in range(count)]


class RawMaster:
    """Sends raw request frames on a virtual line and reads raw reply frames."""

    def __init__(self, endpoint: VirtualEndpoint) -> None:
        self.endpoint = endpoint
        self._buffer = bytearray()

    async def send(self, frame: bytes) -> None:
        """Put *frame* on the line as it is (any bytes, a bad CRC included)."""
        await self.endpoint.send(frame)

    async def send_request(self, unit: int, pdu_hex: str) -> None:
        """Send the request PDU written in hex to *unit*."""
        await self.send(encode_frame(unit, bytes.fromhex(pdu_hex)))

    async def receive_frame(self, wait: float = 5.0) -> bytes | None:
        """The next reply frame, or None if none arrives within *wait* seconds (the default
        is for a reply that is due: long enough for any load)."""
        with anyio.move_on_after(wait):
            while True:
                length = expected_response_length(self._buffer)
                if length == CANNOT_KNOW:
                    # A custom function code: the frame ends with silence.
                    with anyio.move_on_after(0.03) as quiet:
                        self._buffer += await self.endpoint.receive()
                    if quiet.cancelled_caught:
                        frame = bytes(self._buffer)
                        self._buffer.clear()
                        return frame
                    continue
                if 0 < length <= len(self._buffer):
                    frame = bytes(self._buffer[:length])
                    del self._buffer[:length]
                    return frame
                self._buffer += await self.endpoint.receive()
        return None

    async def request(self, unit: int, pdu_hex: str) -> str:
        """Send a request that is due a reply and return the reply PDU in hex (``""`` if
        none came)."""
        await self.send_request(unit, pdu_hex)
        frame = await self.receive_frame()
        if frame is None:
            return ""
        decoded = decode_frame(frame)
        assert decoded.unit == unit
        return decoded.pdu.hex(" ").upper()

    async def assert_silent_then_alive(self) -> None:
        """Check that nothing was answered so far, using a read that must be answered next."""
        await anyio.sleep(0.03)
        await self.send_request(UNIT, "07")
        frame = await self.receive_frame()
        assert frame is not None
        assert decode_frame(frame).pdu[0] == 0x07, frame.hex(" ")


@asynccontextmanager
async def slave_line(
    units: Mapping[int, DataStore] | None = None, **options: Any
) -> AsyncIterator[tuple[RawMaster, Slave]]:
    """A running slave (unit 17 with :func:`example_store` unless *units*) and a raw master."""
    master_end, slave_end = virtual_pair()
    options.setdefault("frame_gap", 0.0)
    options.setdefault("frame_silence", 0.005)
    slave = Slave(slave_end, units if units is not None else {UNIT: example_store()}, **options)
    async with slave:
        # The receiver starts by waiting for silence (INIT): let it see some first.
        await anyio.sleep(options["frame_silence"] + 0.015)
        yield RawMaster(master_end), slave
    await master_end.aclose()
