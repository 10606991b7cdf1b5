"""TLS for the pushed Modbus/TCP Security connections, done by the connection itself: an
`ssl.SSLObject` over two `ssl.MemoryBIO`s, on a plain asyncio transport.

asyncio's own TLS transport (`loop.start_tls`, `ssl=` of `connect_accepted_socket`) is a
general-purpose layer in pure Python: a pushed master or server paid about half of a request's
TLS cost in it. `TlsBioTransport` does only what a Modbus connection needs. It is the plain
transport's protocol and the stream's transport at once:

- bytes received (into a buffer of its own: `asyncio.BufferedProtocol`, no bytes object made
  per receive) go into the incoming BIO, and each record's plaintext out of `read()` goes to the
  stream's protocol (`data_received`), until the BIO holds no whole record;
- a write is `SSLObject.write`, and the outgoing BIO's bytes go to the plain transport in one
  `write`; flow control (`pause_writing`, `resume_writing`) and `pause_reading` pass through.

Its states (`_State`) and their moves are one table, `_NEXT`:

- HANDSHAKING until the handshake ends; a failure writes the alert OpenSSL leaves in the outgoing
  BIO (why the certificate was refused, in TLS's words) before it closes the connection, so the
  peer can name the reason; the caller bounds the handshake's time (`handshake()`);
- OPEN while records flow; an error in a record (an alert received, a bad record) ends it with
  the `ssl.SSLError`, the alert written first;
- CLOSED after the peer's close_notify or end of stream (a stream ended without close_notify
  is taken as an end, as asyncio's and anyio's non-strict TLS streams take it: a Modbus ADU
  carries its own length, so a cut one is never taken for whole), after an error, or after
  `close()`, which sends close_notify first. Bytes that come in after it are dropped unread: a
  peer flooding a refused connection costs nothing.

Renegotiation is refused by the contexts (`ssl.OP_NO_RENEGOTIATION`, see `_tls.py`); OpenSSL
answers a request for it with its alert, which goes out like any other bytes of the outgoing BIO.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import ssl
from typing import Any, Final, Protocol

__all__ = ("PlaintextProtocol", "TlsBioTransport")

_RECORD: Final = 16384
"""The most plaintext one TLS record holds: what one `read()` asks for, so that it takes a whole
record's and the SSLObject keeps none (its `pending()` need not be asked)."""

_RECEIVE: Final = 5 + 16384 + 2048
"""The buffer the plain transport receives into (asyncio's `BufferedProtocol`: no bytes object
made per receive), as long as the longest record on the wire (header, plaintext, TLS 1.2's most
expansion): what a connection holds for it, however many a server has."""


class _State(enum.Enum):
    HANDSHAKING = "handshaking"
    OPEN = "open"
    CLOSED = "closed"


class _Event(enum.Enum):
    HANDSHAKE_DONE = "the handshake finished"
    FAILED = "a TLS error"
    PEER_CLOSED = "the peer's close_notify or end of stream"
    CLOSE = "close() or abort()"
    LOST = "the plain connection was lost"


_HANDSHAKING, _OPEN, _CLOSED = _State.HANDSHAKING, _State.OPEN, _State.CLOSED

_NEXT: Final[dict[tuple[_State, _Event], _State]] = {
    (_HANDSHAKING, _Event.HANDSHAKE_DONE): _OPEN,
    (_HANDSHAKING, _Event.FAILED): _CLOSED,
    (_HANDSHAKING, _Event.PEER_CLOSED): _CLOSED,
    (_HANDSHAKING, _Event.CLOSE): _CLOSED,
    (_HANDSHAKING, _Event.LOST): _CLOSED,
    (_OPEN, _Event.FAILED): _CLOSED,
    (_OPEN, _Event.PEER_CLOSED): _CLOSED,
    (_OPEN, _Event.CLOSE): _CLOSED,
    (_OPEN, _Event.LOST): _CLOSED,
    (_CLOSED, _Event.CLOSE): _CLOSED,
    (_CLOSED, _Event.LOST): _CLOSED,
}
"""Every move of a TLS connection; a (state, event) pair not here is a bug (`RuntimeError`)."""


class PlaintextProtocol(Protocol):
    """What a `TlsBioTransport` hands the plaintext and the connection's events to: the methods
    of an `asyncio.Protocol` (any protocol, buffered or not, that also has `data_received`)."""

    def data_received(self, data: bytes) -> None: ...
    def eof_received(self) -> bool | None: ...
    def connection_lost(self, exc: Exception | None) -> None: ...
    def pause_writing(self) -> None: ...
    def resume_writing(self) -> None: ...


class TlsBioTransport(asyncio.Transport, asyncio.BufferedProtocol):
    """A TLS connection over a plain asyncio transport (see the module docstring): give it as
    the protocol of the plain connection, then await `handshake()`; `app` is the protocol that gets
    the plaintext. `server_hostname` is the name a client checks the server's certificate
    against (None on a server's side)."""

    def __init__(
        self,
        context: ssl.SSLContext,
        app: PlaintextProtocol,
        *,
        server_side: bool = False,
        server_hostname: str | None = None,
    ) -> None:
        super().__init__()
        self._incoming = ssl.MemoryBIO()
        self._outgoing = ssl.MemoryBIO()
        self._sslobj = context.wrap_bio(
            self._incoming, self._outgoing, server_side=server_side,
            server_hostname=server_hostname,
        )  # fmt: skip
        self._buffer = memoryview(bytearray(_RECEIVE))
        self._app = app
        self._app_lost = False
        self._state = _HANDSHAKING
        self._plain: asyncio.Transport | None = None
        self._handshake: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    @property
    def state(self) -> str:
        """The connection's state: "handshaking", "open" or "closed"."""
        return self._state.value

    def _move(self, event: _Event) -> None:
        try:
            self._state = _NEXT[self._state, event]
        except KeyError:
            raise RuntimeError(f"TLS: no move from {self._state.value} on {event.value}") from None

    # -- the handshake ------------------------------------------------------------------

    async def handshake(self) -> None:
        """Wait until the handshake has finished; raise its failure (an `ssl.SSLError`, or a
        `ConnectionError` when the peer left during it). Cancelled (its time is up), it drops
        the connection."""
        try:
            await self._handshake
        except BaseException:
            if self._state is _HANDSHAKING:
                self.abort()
            raise

    def _step_handshake(self) -> None:
        try:
            self._sslobj.do_handshake()
        except ssl.SSLWantReadError:
            self._flush()
            return
        except ssl.SSLError as error:
            self._fail(error)
            return
        self._flush()
        self._move(_Event.HANDSHAKE_DONE)
        if not self._handshake.done():
            self._handshake.set_result(None)
        if self._incoming.pending:  # the peer's first records came with its last handshake one
            self._read()

    # -- the plain transport's protocol ----------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._plain = transport
        self._step_handshake()

    def get_buffer(self, sizehint: int) -> memoryview:
        return self._buffer

    def buffer_updated(self, nbytes: int) -> None:
        """`nbytes` came into the buffer: into the incoming BIO with them."""
        state = self._state
        if state is _OPEN:
            self._incoming.write(self._buffer[:nbytes])
            self._read()
        elif state is _HANDSHAKING:
            self._incoming.write(self._buffer[:nbytes])
            self._step_handshake()
        # CLOSED: dropped unread (see the module docstring)

    def _read(self) -> None:
        """Hand each record's plaintext in the incoming BIO to the app, in order."""
        read, incoming = self._sslobj.read, self._incoming
        while True:
            try:
                chunk = read(_RECORD)
            except ssl.SSLWantReadError:
                break
            except ssl.SSLZeroReturnError:
                self._peer_closed()
                return
            except ssl.SSLError as error:
                self._fail(error)
                return
            if not chunk:
                self._peer_closed()
                return
            self._app.data_received(chunk)
            if self._state is not _OPEN:  # the app closed the connection
                return
            if not incoming.pending:  # read() took the whole record: nothing left in the SSLObject
                break
        if self._outgoing.pending:  # OpenSSL's answer to a post-handshake message
            self._flush()

    def eof_received(self) -> bool:
        if self._state is _HANDSHAKING:
            self._fail(ConnectionResetError("the peer closed the connection during the handshake"))
        elif self._state is _OPEN:
            self._peer_closed()
        return False  # the plain transport closes itself

    def connection_lost(self, exc: Exception | None) -> None:
        if self._state is _HANDSHAKING:
            self._fail(exc or ConnectionResetError("the connection was lost during the handshake"))
        self._move(_Event.LOST)
        self._plain = None
        self._tell_lost(exc)

    def pause_writing(self) -> None:
        self._app.pause_writing()

    def resume_writing(self) -> None:
        self._app.resume_writing()

    # -- endings -----------------------------------------------------------------------

    def _fail(self, error: BaseException) -> None:
        """End the connection with `error`: the alert OpenSSL wrote goes out first."""
        handshaking = self._state is _HANDSHAKING
        self._flush()
        self._move(_Event.FAILED)
        if handshaking:
            if not self._handshake.done():
                self._handshake.set_exception(error)
            self._app_lost = True  # the app never had the connection
        else:
            self._tell_lost(error)
        if self._plain is not None:
            self._plain.close()

    def _peer_closed(self) -> None:
        """The peer's close_notify, or its end of stream: the app sees its end, and
        close_notify goes back."""
        self._move(_Event.PEER_CLOSED)
        self._shutdown()
        self._app.eof_received()  # whatever it answers: TLS has no half-close here
        if self._plain is not None:
            self._plain.close()

    def _tell_lost(self, exc: BaseException | None) -> None:
        if not self._app_lost:
            self._app_lost = True
            self._app.connection_lost(exc)  # type: ignore[arg-type]  # an SSLError is an OSError

    def _shutdown(self) -> None:
        """Write close_notify (the peer's is not waited for)."""
        # Raises when it wants the peer's close_notify, or the session is broken: not waited for.
        with contextlib.suppress(ssl.SSLError):
            self._sslobj.unwrap()
        self._flush()

    def _flush(self) -> None:
        if self._outgoing.pending and self._plain is not None:
            self._plain.write(self._outgoing.read())

    # -- the app's transport -------------------------------------------------------------

    def write(self, data: bytes | bytearray | memoryview) -> None:
        """Send `data` in TLS records, written to the plain transport in one call."""
        if self._state is not _OPEN:
            raise RuntimeError(f"TLS: cannot write while {self._state.value}")
        self._sslobj.write(data)
        self._plain.write(self._outgoing.read())  # type: ignore[union-attr]  # set while OPEN

    def close(self) -> None:
        """Send close_notify (once the handshake has finished) and close the connection."""
        if self._state is _OPEN:
            self._move(_Event.CLOSE)
            self._shutdown()
        elif self._state is _HANDSHAKING:
            self._give_up()
        if self._plain is not None:
            self._plain.close()

    def abort(self) -> None:
        """Drop the connection at once, unsent bytes and all."""
        if self._state is _HANDSHAKING:
            self._give_up()
        elif self._state is _OPEN:
            self._move(_Event.CLOSE)
        if self._plain is not None:
            self._plain.abort()

    def _give_up(self) -> None:
        """Closed in the handshake: whoever waits for it is told, the app never had it."""
        self._move(_Event.CLOSE)
        self._app_lost = True
        if not self._handshake.done():
            self._handshake.set_exception(
                ConnectionAbortedError("the connection was closed during the handshake")
            )
            self._handshake.exception()  # told if awaited, never logged as unretrieved

    def is_closing(self) -> bool:
        return self._state is _CLOSED

    def pause_reading(self) -> None:
        if self._plain is not None:
            self._plain.pause_reading()

    def resume_reading(self) -> None:
        if self._plain is not None:
            self._plain.resume_reading()

    def is_reading(self) -> bool:
        return self._plain is not None and self._plain.is_reading()

    def can_write_eof(self) -> bool:
        return False

    def get_write_buffer_size(self) -> int:
        return 0 if self._plain is None else self._plain.get_write_buffer_size()

    def set_write_buffer_limits(self, high: int | None = None, low: int | None = None) -> None:
        if self._plain is not None:
            self._plain.set_write_buffer_limits(high, low)

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        """`ssl_object`, `peercert`, `cipher` and `compression` of the TLS session, the rest
        (`peername`, `sockname`, `socket`) of the plain transport."""
        if name == "ssl_object":
            return self._sslobj
        if name == "peercert":
            return self._sslobj.getpeercert()
        if name == "cipher":
            return self._sslobj.cipher()
        if name == "compression":
            return self._sslobj.compression()
        if self._plain is None:
            return default
        return self._plain.get_extra_info(name, default)
