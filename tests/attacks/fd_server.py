"""Run by `test_fd_exhaustion.py` in a process of its own: every stream listener of
`tests/attacks/listeners.py`, with a connection limit (5,000 unless given) far above a file
limit of 192 descriptors.

Prints each listener's address as one JSON line on stdout, logs the library's warnings on
stderr, and serves until its standard input closes."""

from __future__ import annotations

import json
import logging
import resource
import subprocess
import sys
from pathlib import Path

import anyio

from tests.attacks.listeners import STREAMS, listeners

FILE_LIMIT = 192
ROOT = Path(__file__).resolve().parents[2]


def start(directory: Path, backend: str, *limit: str) -> tuple[subprocess.Popen[bytes], dict]:
    """This module in a process of its own (the caller kills it); it and the listeners'
    addresses, by name."""
    command = [sys.executable, "-m", "tests.attacks.fd_server", str(directory), backend, *limit]
    process = subprocess.Popen(
        command, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    assert process.stdout is not None
    return process, json.loads(process.stdout.readline())


async def main(directory: str, limit: int) -> None:
    async with listeners(Path(directory), STREAMS, max_connections=limit) as targets:
        print(json.dumps({name: target.address for name, target in targets.items()}), flush=True)
        await anyio.to_thread.run_sync(sys.stdin.read)


if __name__ == "__main__":
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (FILE_LIMIT, hard))
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    limit = int(sys.argv[3]) if len(sys.argv) > 3 else 5000
    anyio.run(main, sys.argv[1], limit, backend=sys.argv[2])
