"""Python calls per gateway request: a figure that does not move with the machine's load.

    python benchmarks/calls_gateway.py [--src SRC] [--seconds 3] [--top 0]

The gateway runs in this process (from `SRC`, the `src` folder of a checkout; this one's by
default) in front of pymodbus's RTU server on a socat pty pair at 115200 8N1, with the 1 ms
pause before a request (`frame_gap=0.001`); 8 Modbus TCP clients in a thread of their own
read 10 holding registers each, one request at a time. While they run, `sys.setprofile` in
the gateway's thread counts every Python function call and coroutine resumption; the
figure is that count over the requests served, with the share of each part (asyncio's
event loop, anyio, the gateway, the master, the line, the core). `--top N` lists the N
functions called most per request.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import threading
import time
import types

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def _part(name: str) -> str:
    if "asyncio/" in name or "selectors" in name:
        return "asyncio"
    if "anyio" in name or "sniffio" in name:
        return "anyio"
    if name.startswith("aiortu/"):
        return name.split(":", maxsplit=1)[0].rsplit("/", 1)[0]
    return "other"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--src", default=None, help="the src folder to import aiortu from")
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--top", type=int, default=0)
    args = parser.parse_args()
    if args.src:
        sys.path.insert(0, args.src)
    import anyio
    import bench_gateway
    import benchlib

    from aiortu.gateway import gateway

    counts: collections.Counter[str] = collections.Counter()

    def profile(frame: types.FrameType, event: str, arg: object) -> None:
        if event == "call":
            path = frame.f_code.co_filename
            name = path.split("/site-packages/")[-1].split("/src/")[-1]
            counts[f"{name}:{frame.f_code.co_name}"] += 1

    with benchlib.Children() as children:
        near, far = children.socat_pair()
        children.server("pymodbus", far, "--baudrate", "115200", "--stopbits", "1")
        port = bench_gateway.free_port()
        warm, done = threading.Event(), threading.Event()

        def clients() -> None:
            time.sleep(1.0)
            bench_gateway.run_clients(port, 8, 0.5, warmup=0.0)
            warm.set()
            bench_gateway.run_clients(port, 8, args.seconds, warmup=0.0)
            done.set()

        async def serve() -> None:
            listen = [f"tcp://127.0.0.1:{port}"]
            options = {"baudrate": 115200, "parity": "N", "stopbits": 1, "retries": 0}
            async with gateway(near, listen, timeout=0.5, frame_gap=0.001, **options) as server:
                thread = threading.Thread(target=clients)
                thread.start()
                await anyio.to_thread.run_sync(warm.wait)
                before = server.counters.requests
                sys.setprofile(profile)
                # The clients' thread signals a threading.Event: polled, not awaited.
                while not done.is_set():  # noqa: ASYNC110
                    await anyio.sleep(0.05)
                sys.setprofile(None)
                requests = server.counters.requests - before
                await anyio.to_thread.run_sync(thread.join)
            _report(counts, requests, args.top)

        anyio.run(serve)


def _report(counts: collections.Counter[str], requests: int, top: int) -> None:
    parts: collections.Counter[str] = collections.Counter()
    for name, count in counts.items():
        parts[_part(name)] += count
    total = sum(counts.values())
    print(f"requests: {requests}; Python calls per request: {total / requests:.1f}")
    for part, count in parts.most_common():
        print(f"  {count / requests:6.1f}  {part}")
    for name, count in counts.most_common(top):
        print(f"  {count / requests:6.2f}  {name}")


if __name__ == "__main__":
    main()
