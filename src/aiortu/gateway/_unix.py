"""`unix:PATH` listeners: Modbus TCP framing over a Unix socket, for programs on the host."""

from __future__ import annotations

import errno
import os
import socket
import stat

import anyio
import anyio.abc

from aiortu.errors import InvalidValue, PortBusy, PortError, PortNotFound, PortPermissionDenied

__all__ = ("UNIX_PREFIX", "listen_unix", "remove_socket", "unix_path")

UNIX_PREFIX = "unix:"


def unix_path(url: str) -> str | None:
    """The socket path of a `unix:PATH` listen URL, None for another URL."""
    if not url.startswith(UNIX_PREFIX):
        return None
    path = url[len(UNIX_PREFIX) :]
    if not path or "\0" in path:
        raise InvalidValue("listen", url, "unix:PATH", "the socket path is missing")
    return path


def _in_use(path: str) -> bool:
    """Whether a program listens on the socket `path` (anyio replaces any socket file there,
    a stale one left by a gateway that was killed, but a live one must stay)."""
    try:
        if not stat.S_ISSOCK(os.stat(path).st_mode):
            return False
    except OSError:
        return False
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        try:
            probe.connect(path)
        except OSError:
            return False
    return True


async def listen_unix(path: str, url: str) -> anyio.abc.Listener[anyio.abc.ByteStream]:
    """Listen on the Unix socket `path`, replacing a stale socket file there.

    Raises [`PortBusy`][aiortu.errors.PortBusy] when a program listens on it or another file
    is in the way, [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] and
    [`PortNotFound`][aiortu.errors.PortNotFound] (no such directory)."""
    if _in_use(path):
        raise PortBusy(url, "a program listens on that socket")
    try:
        return await anyio.create_unix_listener(path)
    except OSError as exc:
        raise _error(url, exc) from exc


def _error(url: str, exc: OSError) -> PortError:
    if exc.errno == errno.EADDRINUSE:
        return PortBusy(url, "a file that is not a socket is in the way")
    if exc.errno == errno.EACCES:
        return PortPermissionDenied(url, "no permission to create the socket there")
    if exc.errno == errno.ENOENT:
        return PortNotFound(url, "the socket's directory does not exist")
    return PortNotFound(url, f"cannot listen: {exc.strerror or exc}")


def remove_socket(path: str) -> None:
    """Remove the socket file `path` the gateway created (gone already: nothing to do)."""
    try:
        if stat.S_ISSOCK(os.stat(path).st_mode):
            os.unlink(path)
    except OSError:
        pass
