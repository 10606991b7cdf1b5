"""A byte stream over a non-blocking file descriptor, such as either end of a pseudo-terminal.

[`FileDescriptorStream`][aiortu.transport.FileDescriptorStream] turns a raw descriptor into an
`anyio.abc.ByteStream` so that the rest of aiortu (the pty test bench, a link over a device node
opened by hand) can use it like any other transport. It waits for readiness with
`anyio.wait_readable` / `anyio.wait_writable`, so it runs under asyncio and trio alike.

End of stream: when the peer of a pseudo-terminal is gone, Linux reports `EIO` on read (and some
systems return `b""`). Both end the stream:
[`receive`][aiortu.transport.FileDescriptorStream.receive] raises `anyio.EndOfStream`. A failing
write raises `anyio.BrokenResourceError`.
"""

from __future__ import annotations

import errno
import os

import anyio
import anyio.abc
import anyio.lowlevel

__all__ = ("FileDescriptorStream",)

_END_OF_STREAM_ERRNOS = frozenset({errno.EIO, errno.ENXIO})


class FileDescriptorStream(anyio.abc.ByteStream):
    """A byte stream that reads and writes one non-blocking file descriptor.

    `fd` is switched to non-blocking mode. With `owns_fd` (the default)
    [`aclose`][aiortu.transport.FileDescriptorStream.aclose] closes the descriptor; otherwise the
    caller keeps ownership and closing the stream only stops it from being used.

    One task may receive while another sends; two concurrent receivers (or senders) raise
    `anyio.BusyResourceError`.
    """

    def __init__(self, fd: int, *, owns_fd: bool = True) -> None:
        os.set_blocking(fd, False)
        self._fd = fd
        self._owns_fd = owns_fd
        self._closed = False
        self._receive_guard = anyio.ResourceGuard("reading from")
        self._send_guard = anyio.ResourceGuard("writing to")

    @property
    def fd(self) -> int:
        """The file descriptor this stream reads and writes."""
        return self._fd

    @property
    def closed(self) -> bool:
        """True once [`aclose`][aiortu.transport.FileDescriptorStream.aclose] was called."""
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise anyio.ClosedResourceError

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """Wait until the descriptor is readable and return up to `max_bytes` bytes.

        Raises `anyio.EndOfStream` when the other side is gone (`EIO` or an empty
        read), `anyio.BrokenResourceError` on any other read error and
        `anyio.ClosedResourceError` if this stream was closed, also while waiting.
        """
        with self._receive_guard:
            while True:
                self._check_open()
                try:
                    data = os.read(self._fd, max_bytes)
                except BlockingIOError:
                    await anyio.wait_readable(self._fd)
                    continue
                except OSError as exc:
                    if exc.errno in _END_OF_STREAM_ERRNOS:
                        raise anyio.EndOfStream from exc
                    raise anyio.BrokenResourceError from exc
                if not data:
                    raise anyio.EndOfStream
                return data

    async def send(self, item: bytes) -> None:
        """Write all of `item`, waiting for the descriptor to become writable when it is full.

        Raises `anyio.BrokenResourceError` when the write fails (the other side is
        gone, or any other OS error) and `anyio.ClosedResourceError` if this stream
        was closed, also while waiting.
        """
        with self._send_guard:
            view = memoryview(item)
            while True:
                self._check_open()
                if not view:
                    return
                try:
                    written = os.write(self._fd, view)
                except BlockingIOError:
                    await anyio.wait_writable(self._fd)
                    continue
                except OSError as exc:
                    raise anyio.BrokenResourceError from exc
                view = view[written:]

    async def send_eof(self) -> None:
        """Not supported: a serial line has no half-close. Always raises NotImplementedError."""
        raise NotImplementedError("a file descriptor stream cannot send an end of file")

    async def aclose(self) -> None:
        """Close the stream and, if it owns the descriptor, the descriptor.

        Tasks waiting in [`receive`][aiortu.transport.FileDescriptorStream.receive] or
        [`send`][aiortu.transport.FileDescriptorStream.send] get `anyio.ClosedResourceError`.
        Closing twice is harmless.
        """
        if self._closed:
            return
        self._closed = True
        # Waiters must be woken before the number is released, or a new file could be
        # opened under the same number while they still wait on it.
        anyio.notify_closing(self._fd)
        if self._owns_fd:
            os.close(self._fd)
        await anyio.lowlevel.checkpoint()
