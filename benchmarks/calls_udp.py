"""Python calls per Modbus UDP read (or Modbus TCP, or Modbus/TCP Security), master and server:
figures that do not move with load.

    python benchmarks/calls_udp.py [--src SRC] [--scheme udp|tcp|tls] [--requests 500]
        [--top 0] [--opcodes]

aiortu's master and aiortu's server (`serve("udp://127.0.0.1:0")`, or `tcp://`, or `tls://`
with certificates made for the run, unit 1) run in this process, each in a thread with an
event loop of its own, from `SRC` (the `src` folder of a checkout; this one's by default).
The master reads 10 holding registers `--requests` times; `sys.setprofile`, set in each thread,
counts every Python function call and coroutine resumption of that thread. The figures are the
counts per read, with the share of each part (asyncio's event loop, anyio, the packages of
aiortu). `--top N` lists the N functions called most per read on each side. `--opcodes` counts
the bytecode instructions run instead (`sys.settrace` with opcode events), which weighs each
function by its work.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import threading
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

_Profile = Callable[[types.FrameType, str, object], None]


def _part(name: str) -> str:
    if "asyncio/" in name or "selectors" in name:
        return "asyncio"
    if "anyio" in name or "sniffio" in name:
        return "anyio"
    if name.startswith("aiortu/"):
        return name.split(":", maxsplit=1)[0].rsplit("/", 1)[0]
    return "other"


def _counter(counts: collections.Counter[str]) -> _Profile:
    def profile(frame: types.FrameType, event: str, arg: object) -> None:
        if event == "call":
            path = frame.f_code.co_filename
            name = path.split("/site-packages/")[-1].split("/src/")[-1]
            counts[f"{name}:{frame.f_code.co_name}"] += 1

    return profile


def _opcode_counter(counts: collections.Counter[str]) -> _Profile:
    def trace(frame: types.FrameType, event: str, arg: object) -> _Profile:
        frame.f_trace_opcodes = True
        frame.f_trace_lines = False
        if event == "opcode":
            path = frame.f_code.co_filename
            name = path.split("/site-packages/")[-1].split("/src/")[-1]
            counts[f"{name}:{frame.f_code.co_name}"] += 1
        return trace

    return trace


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--src", default=None, help="the src folder to import aiortu from")
    parser.add_argument("--scheme", choices=("udp", "tcp", "tls"), default="udp")
    parser.add_argument("--requests", type=int, default=500)
    parser.add_argument("--top", type=int, default=0)
    parser.add_argument("--opcodes", action="store_true", help="count bytecode instructions")
    args = parser.parse_args()
    start: Callable[[_Profile | None], None] = sys.settrace if args.opcodes else sys.setprofile  # type: ignore[assignment]
    counter = _opcode_counter if args.opcodes else _counter
    if args.src:
        sys.path.insert(0, args.src)
    with tempfile.TemporaryDirectory() as directory:
        server_options, master_options = _options(args.scheme, Path(directory))
        _run(args, start, counter, server_options, master_options)


def _options(scheme: str, directory: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The server's and the master's options for `scheme`: over TLS, certificates made in
    `directory` (an operator's role, allowed to read)."""
    if scheme != "tls":
        return {}, {}
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.transport.certificates import Authority

    import aiortu

    ca = Authority(directory)
    server, client = ca.issue("server", server=True), ca.issue("operator", role="operator")
    rules = aiortu.transport.RoleRules({"operator": aiortu.transport.AccessRule(frozenset({3}))})
    pki = {"cafile": ca.cafile}
    return (
        {**pki, "certfile": server.certfile, "keyfile": server.keyfile, "rules": rules},
        {**pki, "certfile": client.certfile, "keyfile": client.keyfile},
    )


def _run(
    args: argparse.Namespace,
    start: Callable[[_Profile | None], None],
    counter: Callable[[collections.Counter[str]], _Profile],
    server_options: dict[str, Any],
    master_options: dict[str, Any],
) -> None:
    import anyio
    import anyio.to_thread

    import aiortu

    master_counts: collections.Counter[str] = collections.Counter()
    server_counts: collections.Counter[str] = collections.Counter()
    counting = threading.Event()
    ready: list[int] = []
    started, done = threading.Event(), threading.Event()

    async def serve() -> None:
        store = aiortu.MemoryStore(holding_registers={0: list(range(40))})
        url = f"{args.scheme}://127.0.0.1:0"
        async with aiortu.serve(url, {1: store}, **server_options) as server:
            ready.append(server.port)
            started.set()
            await anyio.to_thread.run_sync(counting.wait)
            start(counter(server_counts))
            await anyio.to_thread.run_sync(done.wait)
            start(None)

    async def read() -> None:
        await anyio.to_thread.run_sync(started.wait)
        url = f"{args.scheme}://127.0.0.1:{ready[0]}"
        async with aiortu.open_master(url, timeout=2.0, **master_options) as master:
            for _ in range(20):
                await master.read_holding_registers(1, 0, 10)
            counting.set()
            await anyio.sleep(0.2)  # the server's thread sets its profile meanwhile
            start(counter(master_counts))
            for _ in range(args.requests):
                await master.read_holding_registers(1, 0, 10)
            start(None)
        done.set()

    server = threading.Thread(target=anyio.run, args=(serve,))
    server.start()
    anyio.run(read)
    server.join()
    unit = "bytecode instructions" if args.opcodes else "Python calls"
    _report("master", master_counts, args.requests, args.top, unit)
    _report("server", server_counts, args.requests, args.top, unit)


def _report(
    side: str, counts: collections.Counter[str], requests: int, top: int, unit: str
) -> None:
    parts: collections.Counter[str] = collections.Counter()
    for name, count in counts.items():
        parts[_part(name)] += count
    total = sum(counts.values())
    print(f"{side}: {requests} reads; {unit} per read: {total / requests:.1f}")
    for part, count in parts.most_common():
        print(f"  {count / requests:6.1f}  {part}")
    for name, count in counts.most_common(top):
        print(f"  {count / requests:6.2f}  {name}")


if __name__ == "__main__":
    main()
