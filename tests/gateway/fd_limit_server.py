"""Run by `test_fd_limit.py` in a process of its own: a gateway (a TCP listener, a Unix one
and the metrics responder) and a Modbus TCP server, with a file limit of 128 descriptors.

Prints the addresses as one JSON line on stdout, logs the library's warnings on stderr, and
serves until its standard input closes."""

from __future__ import annotations

import json
import logging
import resource
import sys

import anyio

from aiortu.core.serial import LineSettings
from aiortu.gateway import gateway
from aiortu.master import Master
from aiortu.slave import Slave, serve
from aiortu.testing import VirtualBus
from tests.slave.tcp_helpers import UNIT, device

FILE_LIMIT = 128


async def main(unix_path: str) -> None:
    bus = VirtualBus(2)
    slave = Slave(bus.endpoints[1], {UNIT: device()}, frame_gap=0.0, frame_silence=0.005)
    master = Master(bus.endpoints[0], LineSettings(1_000_000), frame_gap=0, timeout=0.5)
    listen = ["tcp://127.0.0.1:0", f"unix:{unix_path}"]
    async with (
        slave,
        master,
        gateway(master, listen, max_connections=5000, metrics="http://127.0.0.1:0/metrics") as gw,
        serve("tcp://127.0.0.1:0", {UNIT: device()}, max_connections=5000) as server,
    ):
        assert gw.metrics_address is not None
        ports = {"gateway": gw.port, "metrics": gw.metrics_address[1], "serve": server.port}
        print(json.dumps(ports), flush=True)
        await anyio.to_thread.run_sync(sys.stdin.read)


if __name__ == "__main__":
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (FILE_LIMIT, hard))
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    anyio.run(main, sys.argv[1])
