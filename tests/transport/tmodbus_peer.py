"""tmodbus 1.1.0 as a peer of aiortu's Modbus UDP and Modbus/TCP Security, run by Python 3.12
from a venv of its own (tmodbus needs 3.12; see tests/transport/test_interop_tmodbus.py).

    python tmodbus_peer.py client udp PORT
    python tmodbus_peer.py client tls PORT CERT KEY CAFILE
    python tmodbus_peer.py client ascii DEVICE
    python tmodbus_peer.py server udp
    python tmodbus_peer.py server tls CERT KEY CAFILE
    python tmodbus_peer.py server ascii DEVICE

A client reads holding registers 0..2 of unit 1, writes 7 and 8 at 3, reads 2..4 back and
writes register 0, printing one line per step (`refused CODE` for an exception response); a
server serves unit 1's holding registers 0..9 (initially 0..9) on an ephemeral port of
127.0.0.1 (or the serial DEVICE, 19200 8N2: a pty keeps neither parity nor 7 data bits),
prints `ready PORT`, and runs until killed. Over TLS the server lets only the role
"operator" write (read from the client certificate by tmodbus): others get exception 01.
"""

from __future__ import annotations

import asyncio
import ssl
import sys
from typing import Any

import serialx
import tmodbus
from tmodbus.exceptions import IllegalFunctionError, ModbusResponseError
from tmodbus.pdu import ReadHoldingRegistersPDU, WriteMultipleRegistersPDU, WriteSingleRegisterPDU
from tmodbus.server import AsyncAsciiServer, AsyncTcpServer, AsyncUdpServer, ModbusRequestRouter
from tmodbus.server.handler import RequestContext
from tmodbus.server.security import extract_modbus_role

SERIAL: dict[str, Any] = {
    "baudrate": 19200,
    "bytesize": 8,
    "parity": serialx.Parity.NONE,
    "stopbits": serialx.StopBits.TWO,
}


async def client(kind: str, port: str, tls: list[str]) -> None:
    options: dict[str, Any] = {"unit_id": 1, "timeout": 3.0, "auto_reconnect": False}
    if kind == "udp":
        modbus = tmodbus.create_async_udp_client("127.0.0.1", int(port), **options)
    elif kind == "ascii":
        del options["timeout"]
        modbus = tmodbus.create_async_ascii_client(port, timeout=3.0, **SERIAL, **options)
    else:
        certfile, keyfile, cafile = tls
        context = ssl.create_default_context(cafile=cafile)
        context.load_cert_chain(certfile, keyfile)
        modbus = tmodbus.create_async_tcp_client("127.0.0.1", int(port), ssl=context, **options)
    await modbus.connect()
    try:
        print("read", await modbus.read_holding_registers(0, 3), flush=True)
        await modbus.write_multiple_registers(3, [7, 8])
        print("read", await modbus.read_holding_registers(2, 3), flush=True)
        try:
            await modbus.write_single_register(0, 99)
            print("written", flush=True)
        except ModbusResponseError as error:
            print("refused", error.error_code, flush=True)
    finally:
        await modbus.disconnect()


def router(tls: bool) -> ModbusRequestRouter:
    registers = list(range(10))
    routes = ModbusRequestRouter()

    def may_write(context: RequestContext) -> bool:
        if not tls:
            return True
        role = extract_modbus_role(context.client_cert) if context.client_cert else None
        return role == "operator"

    @routes.register(ReadHoldingRegistersPDU)
    async def read(unit: int, request: ReadHoldingRegistersPDU) -> list[int]:
        return registers[request.start_address : request.start_address + request.quantity]

    @routes.register(WriteSingleRegisterPDU)
    async def write_one(unit: int, request: WriteSingleRegisterPDU, context: RequestContext) -> int:
        if not may_write(context):
            raise IllegalFunctionError(request.function_code)
        registers[request.address] = request.value
        return request.value

    @routes.register(WriteMultipleRegistersPDU)
    async def write_many(
        unit: int, request: WriteMultipleRegistersPDU, context: RequestContext
    ) -> int:
        if not may_write(context):
            raise IllegalFunctionError(request.function_code)
        start = request.start_address
        registers[start : start + len(request.values)] = request.values
        return len(request.values)

    return routes


async def server(kind: str, tls: list[str]) -> None:
    if kind == "ascii":
        line = AsyncAsciiServer(tls[0], router(False), **SERIAL)
        await line.start()
        print("ready 0", flush=True)
        await asyncio.Event().wait()
        return
    if kind == "udp":
        udp = AsyncUdpServer("127.0.0.1", router(False), port=0)
        await udp.start()
        print("ready", udp.sockets[0].getsockname()[1], flush=True)
        await udp.serve_forever()
        return
    certfile, keyfile, cafile = tls
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(certfile, keyfile)
    context.load_verify_locations(cafile=cafile)
    context.verify_mode = ssl.CERT_REQUIRED
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    tcp = AsyncTcpServer("127.0.0.1", router(True), port=0, ssl_context=context)
    await tcp.start()
    assert tcp._server is not None
    print("ready", tcp._server.sockets[0].getsockname()[1], flush=True)
    await tcp.serve_forever()


if __name__ == "__main__":
    role, kind, *rest = sys.argv[1:]
    if role == "client":
        asyncio.run(client(kind, rest[0], rest[1:]))
    else:
        asyncio.run(server(kind, rest))
