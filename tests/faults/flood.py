"""A garbage flood on a pseudo-terminal against a slave, with the process's CPU and RSS.

Shared by the fault suite and ``benchmarks/soak_faults.py``.
"""

from __future__ import annotations

import contextlib
import os
import random
import resource
import time
from dataclasses import dataclass

import anyio
import anyio.lowlevel

import aiortu
from aiortu.core.rtu import encode_frame
from tests.transport.ptys import LINE, open_pty

__all__ = ("FloodResult", "garbage_flood", "rss_bytes")

UNIT = 17
_REQUEST = encode_frame(UNIT, bytes.fromhex("03 00 00 00 02"))
_REPLY = encode_frame(UNIT, bytes.fromhex("03 04 00 07 00 08"))


def rss_bytes() -> int:
    """The process's resident set size now (Linux), else its peak."""
    with contextlib.suppress(OSError, ValueError, IndexError), open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


@dataclass
class FloodResult:
    """What a flood cost and whether the slave came through it."""

    garbage: int
    """Bytes of garbage written."""
    flood_cpu: float
    """Seconds of process CPU while the flood ran."""
    idle_cpu: float
    """Seconds of process CPU in the *idle* seconds after it."""
    idle: float
    rss_growth: int
    """Bytes the resident set grew by from before the flood to after it."""
    answered: bool
    """Whether the slave answered a good request after the flood, right."""
    discarded: int
    """Discards the slave's receiver counted (the garbage reached it)."""


async def garbage_flood(rng: random.Random, size: int, idle: float = 0.3) -> FloodResult:
    """Write *size* bytes of random garbage (with bits of frames in it) to a slave on a
    pty, as fast as the pty takes them; then measure *idle* seconds of quiet, then ask."""
    store = aiortu.MemoryStore(holding_registers={0: [7, 8]})
    with open_pty() as pty:
        async with aiortu.serve(
            pty.path, {UNIT: store}, baudrate=LINE.baudrate, parity="N"
        ) as slave:
            await anyio.sleep(0.05)  # the receiver starts by waiting for silence
            rss_before = rss_bytes()
            cpu_before = time.process_time()
            written = 0
            while written < size:
                chunk = rng.randbytes(rng.randrange(1, 512))
                if rng.random() < 0.2:
                    chunk += _REQUEST[: rng.randrange(1, len(_REQUEST) + 1)]
                with contextlib.suppress(BlockingIOError):
                    written += os.write(pty.master, chunk)
                _drain(pty.master)
                await anyio.lowlevel.checkpoint()
            flood_cpu = time.process_time() - cpu_before
            await anyio.sleep(0.05)
            _drain(pty.master)
            cpu_before = time.process_time()
            await anyio.sleep(idle)
            idle_cpu = time.process_time() - cpu_before
            rss_growth = rss_bytes() - rss_before
            _drain(pty.master)
            answered = await _ask(pty.master)
            discarded = sum(slave.link.discarded.values())
    return FloodResult(written, flood_cpu, idle_cpu, idle, rss_growth, answered, discarded)


def _drain(fd: int) -> None:
    """Read and drop what the slave sent (it may answer a request hidden in the garbage)."""
    with contextlib.suppress(BlockingIOError):
        while os.read(fd, 65536):
            pass


async def _ask(fd: int) -> bool:
    """Send a good request after a silence; whether the right reply comes."""
    await anyio.sleep(0.03)
    os.write(fd, _REQUEST)
    received = b""
    with anyio.move_on_after(2.0):
        while not received.endswith(_REPLY):
            await anyio.wait_readable(fd)
            with contextlib.suppress(BlockingIOError):
                received += os.read(fd, 256)
    return received.endswith(_REPLY)
