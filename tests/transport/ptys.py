"""Pseudo-terminal helpers for the transport tests: a pty whose slave is a serial port."""

from __future__ import annotations

import contextlib
import functools
import os
import termios
from collections.abc import Iterator
from dataclasses import dataclass

import anyio

from aiortu.core.serial import LineSettings

__all__ = ("LINE", "Pty", "open_pty", "pty_keeps_even_parity", "read_master")

LINE = LineSettings(19200, 8, "N", 1)
"""8N1: what the tests use where the format does not matter (see pty_keeps_even_parity)."""


@dataclass
class Pty:
    """Both ends of a pty: the test plays the device on *master*; *path* is the port."""

    master: int
    slave: int
    path: str

    def write(self, data: bytes) -> None:
        """Write as the device: the bytes arrive at the port's receive side."""
        os.write(self.master, data)

    def close_master(self) -> None:
        """Hang up, as an unplugged USB adapter does."""
        with contextlib.suppress(OSError):
            os.close(self.master)
        self.master = -1


@contextlib.contextmanager
def open_pty() -> Iterator[Pty]:
    """A fresh pty, closed at the end. The slave fd stays open so the line never hangs up."""
    master, slave = os.openpty()
    os.set_blocking(master, False)
    pty = Pty(master, slave, os.ttyname(slave))
    try:
        yield pty
    finally:
        for fd in (pty.master, pty.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)


async def read_master(pty: Pty, count: int, limit: float = 2.0) -> bytes:
    """Read exactly *count* bytes the port sent, as the device sees them."""
    data = bytearray()
    with anyio.fail_after(limit):
        while len(data) < count:
            await anyio.wait_readable(pty.master)
            with contextlib.suppress(BlockingIOError):
                data += os.read(pty.master, count - len(data))
    return bytes(data)


@functools.cache
def pty_keeps_even_parity() -> bool:
    """Whether this kernel's ptys keep PARENB. Linux does; some sandboxed kernels refuse it."""
    master, slave = os.openpty()
    try:
        attributes = termios.tcgetattr(slave)
        attributes[2] = (attributes[2] & ~termios.PARODD) | termios.PARENB
        try:
            termios.tcsetattr(slave, termios.TCSANOW, attributes)
        except termios.error:
            return False
        return bool(termios.tcgetattr(slave)[2] & termios.PARENB)
    finally:
        os.close(master)
        os.close(slave)
