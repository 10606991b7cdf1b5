"""Every stream listener under attack, on loopback: what the server's memory does and how soon
a good client is answered again.

Starts `tests/attacks/fd_server.py` (every stream listener of the attack tests in one process,
a connection limit of 5,000 and a file limit of 192 descriptors) and, listener by listener:

- holds 2,000 connections (the file limit makes most of them wait in the backlog or fail
  their accept), then closes them all and times the first good reply after, a client refused
  meanwhile asking again (`recover ms`);
- pipelines 20,000 good requests on 4 connections and reads every reply (`flood s`);
- sends 200 connections of random bytes (seed 1).

The server's RSS (VmRSS from /proc) is read before the first attack, after each listener and at
the end; `VmHWM` is its peak. Run:
`nice -n 10 python benchmarks/bench_attacks.py asyncio|trio MAX_CONNECTIONS` (default asyncio 5000).
"""

from __future__ import annotations

import random
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.attacks import fd_server  # noqa: E402
from tests.attacks.fd_server import FILE_LIMIT  # noqa: E402
from tests.attacks.listeners import STREAMS, Target, ask, open_client  # noqa: E402
from tests.attacks.test_fd_exhaustion import _target  # noqa: E402
from tests.attacks.test_listener_attacks import _close_all, _connect_many  # noqa: E402

MODBUS = [name for name in STREAMS if name != "gateway metrics"]


def _memory(pid: int) -> dict[str, int]:
    """VmRSS and VmHWM of `pid`, in KiB."""
    found = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            found[key] = int(value.split()[0])
    return found


def _pipeline(target: Target, count: int) -> None:
    """Send `count` good requests at once on one connection and read every reply."""
    requests = b"".join(target.request(index) for index in range(count))
    expected = sum(len(target.reply(index)) for index in range(count))
    with open_client(target, 60.0) as sock:
        sock.sendall(requests)
        got = 0
        while got < expected and (chunk := sock.recv(65536)):
            got += len(chunk)


def _garbage(target: Target, generator: random.Random) -> None:
    """Random bytes on a new plain connection (before any TLS handshake), read until the
    server closes or 50 ms of silence (an RTU listener drops noise and keeps the connection)."""
    data = generator.randbytes(generator.randrange(1, 600))
    with socket.socket(socket.AF_UNIX if target.kind == "unix" else socket.AF_INET) as sock:
        sock.settimeout(0.05)
        try:
            sock.connect(target.address)
            sock.sendall(data)
            while sock.recv(65536):
                pass
        except OSError:
            pass


def _recover(target: Target, began: float) -> float:
    """Milliseconds from `began` to the first good reply; a client refused while the server
    still works through the closed connections in its backlog asks again."""
    for _ in range(100):
        try:
            if ask(target, 2.0).startswith(target.reply()):
                return (time.perf_counter() - began) * 1000
        except OSError:
            pass
    raise AssertionError(f"{target.name}: no good reply")


def main(backend: str, limit: str) -> None:
    directory = Path(tempfile.mkdtemp())
    process, addresses = fd_server.start(directory, backend, limit)
    try:
        targets = [_target(name, addresses[name], directory) for name in STREAMS]
        start = _memory(process.pid)
        print(
            f"{backend}, file limit {FILE_LIMIT}, max_connections {limit}:"
            f" RSS at start {start['VmRSS']} KiB"
        )
        print("| listener | recover ms | flood s | RSS after KiB |")
        print("| --- | ---: | ---: | ---: |")
        generator = random.Random(1)
        for target in targets:
            held = _connect_many(target, 2000)
            _close_all(held)
            began = time.perf_counter()
            recover = _recover(target, began)
            flood = 0.0
            if target.name in MODBUS:
                threads = [
                    threading.Thread(target=_pipeline, args=(target, 5000)) for _ in range(4)
                ]
                began = time.perf_counter()
                for thread in threads:
                    thread.start()
                for thread in threads:
                    thread.join()
                flood = time.perf_counter() - began
            for _ in range(200):
                _garbage(target, generator)
            after = _memory(process.pid)["VmRSS"]
            print(f"| {target.name} | {recover:.1f} | {flood:.2f} | {after} |")
        end = _memory(process.pid)
        print(f"RSS at end {end['VmRSS']} KiB, peak {end['VmHWM']} KiB")
    finally:
        process.kill()
        _, err = process.communicate(timeout=10)
    lines = err.decode().splitlines()
    print(f"log lines on stderr: {len(lines)}; tracebacks: {sum('Traceback' in x for x in lines)}")


if __name__ == "__main__":
    main(*sys.argv[1:3]) if len(sys.argv) > 2 else main("asyncio", "5000")
