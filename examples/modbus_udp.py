"""Modbus UDP: the same master and server, one request or reply per datagram.

``aiortu.serve("udp://host:port", ...)`` answers each request datagram to its source;
``aiortu.open_master("udp://host:port")`` sends each request as one datagram, matches replies by
transaction id, drops datagrams from any other address, and retries lost ones. Here both run on
127.0.0.1 and a port the system picks; run it on its own::

    python examples/modbus_udp.py
"""

from __future__ import annotations

import anyio

import aiortu


async def main() -> None:
    store = aiortu.MemoryStore(holding_registers={0: [215, 0, 0, 0]})
    async with (
        aiortu.serve("udp://127.0.0.1:0", {17: store}) as server,
        aiortu.open_master(f"udp://127.0.0.1:{server.port}", timeout=0.5, retries=2) as master,
    ):
        await master.write_registers(17, 1, [7, 8])
        print(f"registers 0..2 = {await master.read_holding_registers(17, 0, 3)}")
        sent = master.link.stream.counters
        print(
            f"requests {sent.requests}, replies {sent.replies}, "
            f"from strangers {sent.strangers}, refused {sent.refused}"
        )


if __name__ == "__main__":
    anyio.run(main)
