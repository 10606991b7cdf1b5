"""Talk to a device behind a serial device server: Modbus RTU frames over TCP.

Serial device servers (Moxa NPort, USR-TCP232 and the like in "TCP server, raw" mode)
pass the RTU bytes, CRC included, through a TCP connection. aiortu opens such a line
with a URL, ``rtu+tcp://host:port``, and everything else stays the same.

Runs on its own: a stand-in for the device server listens on 127.0.0.1 and serves a
simulated unit 17 with an aiortu.Slave over the accepted connection::

    python examples/rtu_over_tcp.py
"""

from __future__ import annotations

import anyio
import anyio.abc

import aiortu

DEVICE = aiortu.MemoryStore(holding_registers={0x6B: [0xAE41, 0x5652, 0x4340]})


async def device_server(listener: anyio.abc.SocketListener) -> None:
    """Serve unit 17 on every connection, as a device server's serial port would."""

    async def serve_connection(stream: anyio.abc.SocketStream) -> None:
        # frame_gap=0: there is no wire to keep quiet on a TCP connection.
        async with aiortu.Slave(stream, {17: DEVICE}, frame_gap=0) as slave:
            await slave.wait_stopped()

    await listener.serve(serve_connection)


async def main() -> None:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(device_server, listener)
        url = f"rtu+tcp://127.0.0.1:{port}"
        async with aiortu.open_master(url, timeout=1.0, frame_gap=0) as master:
            registers = await master.read_holding_registers(17, 0x6B, 3)
            print(f"{url} unit 17 registers 107..109 = {[hex(r) for r in registers]}")
            await master.write_register(17, 0x6B, 1234)
            print(f"after the write: {await master.read_holding_registers(17, 0x6B, 1)}")
        tasks.cancel_scope.cancel()


if __name__ == "__main__":
    anyio.run(main)
