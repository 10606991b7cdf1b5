"""The getting-started slave: unit 1 with four holding registers, printing every write.

Run ``aiortu virtual-bus --link-dir /tmp/rtu`` first, then ``python slave.py`` (or
``python slave.py PORT``); Ctrl-C stops it cleanly.
"""

import sys

import anyio

import aiortu

PORT = sys.argv[1] if len(sys.argv) > 1 else "/tmp/rtu/port1"


async def main() -> None:
    store = aiortu.MemoryStore(holding_registers={0: [215, 0, 0, 0]})
    store.observe(lambda change: print("written:", change.address, change.values, flush=True))
    async with aiortu.serve(PORT, {1: store}, parity="N", stopbits=2):
        print(f"serving unit 1 on {PORT}; Ctrl-C to stop", flush=True)
        await anyio.sleep_forever()


try:
    anyio.run(main)
except KeyboardInterrupt:
    print("stopped")
