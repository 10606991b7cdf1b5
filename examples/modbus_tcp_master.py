"""A master over Modbus TCP: the same calls as on a serial line, to a Modbus TCP server.

``aiortu.open_master("tcp://host:502")`` gives the same master: every request carries the next
transaction id, a reply with another id (a late one, after a timeout) is dropped and counted, and
the connection is reopened with back-off when the server closes it. Here the server is aiortu's
own, on 127.0.0.1 and a port the system picks; run it on its own::

    python examples/modbus_tcp_master.py
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.transport import ModbusTcpStream, PushConnectionStream


async def main() -> None:
    store = aiortu.MemoryStore(holding_registers={0: [215, 0, 0, 0]}, coils={0: [0] * 8})
    async with (
        aiortu.serve("tcp://127.0.0.1:0", {17: store}) as server,
        aiortu.open_master(f"tcp://127.0.0.1:{server.port}", timeout=1.0) as master,
    ):
        await master.write_registers(17, 1, [7, 8])
        print(f"registers 0..2 = {await master.read_holding_registers(17, 0, 3)}")
        device = master.slave(17)
        await device.write_coils(0, [True, False, True])
        print(f"coils 0..3 = {await device.read_coils(0, 4)}")
        try:
            await master.read_holding_registers(17, 100, 2)
        except aiortu.ExceptionResponse as refused:
            print(f"register 100: exception {refused.code:02X}")
        stream = master.link.stream  # pushed on asyncio; a ModbusTcpStream under trio
        assert isinstance(stream, PushConnectionStream | ModbusTcpStream)
        sent = stream.counters
        print(f"requests {sent.requests}, replies {sent.replies}, dropped {sent.dropped}")


if __name__ == "__main__":
    anyio.run(main)
