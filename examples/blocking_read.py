"""Read and write a device without async: a plain script, threads, a notebook.

Runs on its own: a simulated device (unit 17) serves on one port of a virtual bus of
pseudo-terminals, and the master opens the other port by its device path, as it would open
/dev/ttyUSB0. Everything runs in the blocking API's event loop thread; this script never
awaits::

    python examples/blocking_read.py
"""

from __future__ import annotations

import threading

import aiortu
import aiortu.blocking

LINE = {"baudrate": 19200, "parity": "N", "stopbits": 2}  # ptys keep no parity


def main() -> None:
    device = aiortu.MemoryStore(holding_registers={0: 200})
    with (
        aiortu.blocking.pty_bus(2) as bus,
        aiortu.blocking.serve(bus.value.paths[1], {17: device}, **LINE),
        aiortu.blocking.open_master(bus.value.paths[0], timeout=1.0, **LINE) as master,
    ):
        master.write_registers(17, 0x6B, [215, 7, 8])
        print(f"registers 0x6B..0x6D = {master.read_holding_registers(17, 0x6B, 3)}")

        meter = master.slave(17)
        meter.write_float32(0x10, 21.5)
        print(f"float32 at 0x10 = {meter.read_float32(0x10)}")

        # Threads share the master: their requests queue on the line.
        results: dict[int, list[int]] = {}

        def poll(address: int) -> None:
            results[address] = meter.read_holding_registers(address, 2)

        threads = [threading.Thread(target=poll, args=(address,)) for address in (0x6B, 0x10)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        print(f"from two threads: {dict(sorted(results.items()))}")
        print(f"unit 17: {master.unit_stats(17).requests} requests, online {master.is_online(17)}")


if __name__ == "__main__":
    main()
