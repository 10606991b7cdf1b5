"""Serve simulated devices over Modbus TCP, and over RTU framing on a TCP listener.

``aiortu.serve("tcp://0.0.0.0:1502", {17: store})`` answers Modbus TCP clients (SCADA,
pymodbus, mbpoll -m tcp) from the same stores, handlers and hooks as a serial slave, with
many connections at once. ``rtu+tcp://`` with a wildcard host or port 0 listens too, for
serial device servers that connect in; each connection is then a line of its own.

Runs on its own, on 127.0.0.1 and ports the system picks::

    python examples/modbus_tcp_server.py
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.core.mbap import AduDecoder, encode_adu


async def main() -> None:
    store = aiortu.MemoryStore(holding_registers={0: [215, 0, 0, 0]})
    async with aiortu.serve("tcp://127.0.0.1:0", {17: store}) as server:
        server.after_request(lambda request, context, answer: print(f"served {request}"))
        async with await anyio.connect_tcp("127.0.0.1", server.port) as client:
            # Two requests sent at once (pipelined); the replies come back in order,
            # each with its transaction id.
            write = bytes.fromhex("10 0001 0002 04 0007 0008")
            read = bytes.fromhex("03 0000 0003")
            await client.send(encode_adu(1, 17, write) + encode_adu(2, 17, read))
            decoder, replies = AduDecoder(), []
            while len(replies) < 2:
                replies += decoder.feed(await client.receive())
            for reply in replies:
                print(f"Modbus TCP transaction {reply.transaction_id}: reply {reply.pdu.hex(' ')}")

    # The same store, with RTU framing: any aiortu master reaches it with rtu+tcp://.
    async with aiortu.serve("rtu+tcp://127.0.0.1:0", {17: store}) as server:
        url = f"rtu+tcp://127.0.0.1:{server.port}"
        async with aiortu.open_master(url, timeout=1.0, frame_gap=0) as master:
            print(f"RTU over TCP: registers 0..2 = {await master.read_holding_registers(17, 0, 3)}")


if __name__ == "__main__":
    anyio.run(main)
