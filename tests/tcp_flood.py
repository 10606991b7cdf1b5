"""A client that streams requests and never reads: what the kernel can hold for it, and the
sending itself, for the tests of servers that must hold such a client back."""

from __future__ import annotations

import socket
import ssl

__all__ = ("kernel_buffers", "send_until_blocked")


def kernel_buffers() -> int:
    """The most a paused connection can hold in the kernel: the receiver's and the sender's
    buffers at their largest (the tcp_rmem and tcp_wmem maximums)."""
    total = 0
    for name in ("tcp_rmem", "tcp_wmem"):
        with open(f"/proc/sys/net/ipv4/{name}") as file:
            total += int(file.read().split()[2])
    return total


def send_until_blocked(
    sock: socket.socket, chunk: bytes, *, quiet: float, most: int = 64 << 20
) -> int:
    """Send `chunk` over and over without reading; stop once the server has taken nothing
    for `quiet` seconds, closed, or `most` bytes went. Return the bytes sent."""
    sock.settimeout(quiet)
    sent = 0
    while sent < most:
        try:
            sent += sock.send(chunk)
        except (TimeoutError, ConnectionError, ssl.SSLError):
            break
    return sent
