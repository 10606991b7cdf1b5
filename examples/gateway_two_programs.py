"""Two programs share one RS-485 line through the gateway, without knowing of each other.

A device (unit 17) sits on a virtual line; the gateway holds the line's only master and
listens for Modbus TCP. A logger polls three registers while a commissioning tool writes a
setpoint: each has its own TCP connection, and the gateway puts their requests on the line
one at a time, in turn. On real hardware the line is `/dev/ttyUSB0` and the programs are
separate processes on any machine of the network:

    aiortu gateway /dev/ttyUSB0 --listen tcp://0.0.0.0:1502

Run: python examples/gateway_two_programs.py
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.core.mbap import Adu, AduDecoder, encode_adu
from aiortu.slave import Block, MemoryStore, Slave
from aiortu.testing import VirtualBus

UNIT = 17


async def ask(port: int, requests: list[bytes]) -> list[bytes]:
    """One program: connect, send each request PDU to unit 17, return the reply PDUs."""
    replies = []
    decoder = AduDecoder()
    async with await anyio.connect_tcp("127.0.0.1", port) as connection:
        for transaction_id, pdu in enumerate(requests, start=1):
            await connection.send(encode_adu(transaction_id, UNIT, pdu))
            adus: list[Adu] = []
            while not adus:
                adus = decoder.feed(await connection.receive())
            replies.append(adus[0].pdu)
    return replies


async def logger(port: int) -> None:
    """Poll registers 0..2 every 10 ms, print each change; stop once the setpoint is 215."""
    read = bytes.fromhex("03 0000 0003")  # read holding registers 0..2
    last = None
    for _ in range(500):
        (reply,) = await ask(port, [read])
        values = [int.from_bytes(reply[i : i + 2], "big") for i in range(2, 8, 2)]
        if values != last:
            print(f"logger: registers 0..2 = {values}")
            last = values
        if values[0] == 215:
            break
        await anyio.sleep(0.01)


async def commissioning_tool(port: int) -> None:
    (reply,) = await ask(port, [bytes.fromhex("06 0000 00D7")])  # register 0 := 215
    print(f"tool: setpoint written, reply {reply.hex(' ')}")


async def main() -> None:
    bus = VirtualBus(2)
    store = MemoryStore(holding_registers=[Block(0, 8, [20, 7, 8])])
    device = Slave(bus.endpoints[1], {UNIT: store}, frame_gap=0.0)
    master = aiortu.Master(bus.endpoints[0], frame_gap=0.0, turnaround_delay=0.005)
    async with (
        device,
        master,
        aiortu.gateway(master, ["tcp://127.0.0.1:0"]) as gateway,
        anyio.create_task_group() as programs,
    ):
        programs.start_soon(logger, gateway.port)
        programs.start_soon(commissioning_tool, gateway.port)
    print(f"gateway: {gateway.counters.requests} requests, one transaction at a time")
    print(f"the device: setpoint {store.get('holding_registers', 0)[0]}")


if __name__ == "__main__":
    anyio.run(main)
