"""A raw Modbus TCP client for the slave's tests, built from the core's MBAP functions."""

from __future__ import annotations

from collections import deque
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import anyio.abc

from aiortu.core.mbap import Adu, AduDecoder, encode_adu
from aiortu.slave import MemoryStore, ModbusTcpServer, ServerId

__all__ = ("UNIT", "TcpClient", "connect", "device", "tcp_server")

UNIT = 17


def device() -> MemoryStore:
    """A store with something in every table, FIFO, file and identification object."""
    return MemoryStore(
        coils={0: [1, 0, 1, 1] + [0] * 12},
        discrete_inputs={0: [0, 1, 1] + [0] * 5},
        holding_registers={0: [0x1234, 0xABCD, 7] + [0] * 13},
        input_registers={0: [11, 22, 33]},
        fifo_queues={0x04DE: [440, 25]},
        files={4: [0x06AF, 0x04BE, 0x100D, 0, 0, 0]},
        device_identification={0: "aiortu", 1: "SIM", 2: "1.0"},
        server_id=ServerId(b"\x11", True, b"sim"),
        exception_status=0x6D,
    )


class TcpClient:
    """Sends raw requests over one connection and reads the replies as ADUs."""

    def __init__(self, stream: anyio.abc.ByteStream) -> None:
        self.stream = stream
        self._decoder = AduDecoder()
        self._ready: deque[Adu] = deque()

    async def send(self, pdu_hex: str, unit: int = UNIT, transaction_id: int = 1) -> None:
        await self.stream.send(encode_adu(transaction_id, unit, bytes.fromhex(pdu_hex)))

    async def receive(self, wait: float = 3.0) -> Adu | None:
        """The next reply, or None when none comes within *wait* seconds."""
        with anyio.move_on_after(wait):
            while not self._ready:
                self._ready.extend(self._decoder.feed(await self.stream.receive()))
            return self._ready.popleft()
        return None

    async def request(self, pdu_hex: str, unit: int = UNIT, transaction_id: int = 1) -> str:
        """Send one request; return the reply PDU in hex, checking the ids it carries."""
        await self.send(pdu_hex, unit, transaction_id)
        reply = await self.receive()
        assert reply is not None, f"no reply to {pdu_hex}"
        assert (reply.transaction_id, reply.unit) == (transaction_id, unit)
        return reply.pdu.hex(" ").upper()

    async def closed_by_server(self, wait: float = 5.0) -> bool:
        """Whether the server closes the connection within *wait* seconds."""
        with anyio.move_on_after(wait):
            try:
                while True:
                    await self.stream.receive()
            except (anyio.EndOfStream, anyio.BrokenResourceError):
                return True
        return False


@asynccontextmanager
async def connect(server: ModbusTcpServer) -> AsyncIterator[TcpClient]:
    stream = await anyio.connect_tcp("127.0.0.1", server.port)
    async with stream:
        yield TcpClient(stream)


@asynccontextmanager
async def tcp_server(units: Any = None, **options: Any) -> AsyncIterator[ModbusTcpServer]:
    """``aiortu.serve`` on an ephemeral port of 127.0.0.1 (unit 17 with :func:`device`)."""
    from aiortu.slave import serve

    async with serve("tcp://127.0.0.1:0", units or {UNIT: device()}, **options) as server:
        assert isinstance(server, ModbusTcpServer)
        yield server
