"""pymodbus's Modbus UDP, Modbus/TCP Security and ASCII servers, for the transports' interop
tests.

``python pymodbus_peers.py udp`` serves unit 1 over Modbus UDP on an ephemeral port of
127.0.0.1; ``python pymodbus_peers.py tls CERT KEY CAFILE`` serves it over TLS (client
certificates signed by CAFILE required); ``python pymodbus_peers.py ascii DEVICE`` serves it in
Modbus ASCII on a serial device at 19200 8N2 (a pty keeps neither parity nor 7 data bits).
Each prints ``ready PORT`` once it listens (0 for a serial device) and runs until killed. The
tables are those of :mod:`tests.pymodbus_server`.
"""

from __future__ import annotations

import asyncio
import contextlib
import ssl
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from pymodbus import FramerType
from pymodbus.server import ModbusSerialServer, ModbusTlsServer, ModbusUdpServer

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tests.pymodbus_server import _context


def _port(server: ModbusUdpServer | ModbusTlsServer) -> int:
    transport = server.transport
    sockets = getattr(transport, "sockets", None)
    if sockets:
        return int(sockets[0].getsockname()[1])
    return int(transport.get_extra_info("sockname")[1])  # type: ignore[union-attr]


async def serve_ascii(device: str) -> None:
    def connected(up: bool) -> None:
        if up:
            print("ready 0", flush=True)

    server = ModbusSerialServer(
        _context(), framer=FramerType.ASCII, port=device, baudrate=19200, bytesize=8,
        parity="N", stopbits=2, trace_connect=connected,
    )  # fmt: skip
    await server.serve_forever()


async def serve(argv: list[str]) -> None:
    server: ModbusUdpServer | ModbusTlsServer
    if argv[0] == "ascii":
        await serve_ascii(argv[1])
        return
    if argv[0] == "udp":
        server = ModbusUdpServer(_context(), address=("127.0.0.1", 0))
    else:
        certfile, keyfile, cafile = argv[1:4]
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH, cafile=cafile)
        context.load_cert_chain(certfile, keyfile)
        context.verify_mode = ssl.CERT_REQUIRED
        server = ModbusTlsServer(_context(), address=("127.0.0.1", 0), sslctx=context)
    await server.serve_forever(background=True)
    print(f"ready {_port(server)}", flush=True)
    await server.serving


@contextlib.contextmanager
def running(*argv: str) -> Iterator[int]:
    """Run a server in a subprocess for the ``with`` block; yield its port."""
    server = subprocess.Popen(
        [sys.executable, "-W", "ignore", __file__, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert server.stdout is not None
        line = server.stdout.readline().split() or ["(nothing)"]
        if line[0] != "ready":
            raise RuntimeError(f"pymodbus's server did not start: {server.stderr.read()}")
        yield int(line[1])
    finally:
        server.terminate()
        server.wait(timeout=10)


if __name__ == "__main__":
    asyncio.run(serve(sys.argv[1:]))
