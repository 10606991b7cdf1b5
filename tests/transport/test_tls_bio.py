"""The pushed connections' TLS layer (`TlsBioTransport`) between two ends joined by an
in-memory wire: records cut anywhere, the alert of a refused handshake sent before the close,
close_notify and a bare end of stream, a plaintext flood dropped unread, and its state table."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import random
import ssl
from typing import Any

import pytest

from aiortu.slave import _tls_server as tls_server_module
from aiortu.transport import _push_server as push_server_module
from aiortu.transport import client_tls_context, server_tls_context
from aiortu.transport._tls import server_refusal
from aiortu.transport._tls_bio import _NEXT, TlsBioTransport, _Event, _State
from tests.transport.test_tls import pki, tls_master, tls_server

pytestmark = pytest.mark.timeout(60)

__all__ = ("pki",)


class _Wire(asyncio.Transport):
    """One end's plain transport: what it was asked to do, in order."""

    def __init__(self) -> None:
        super().__init__()
        self.sent = bytearray()
        self.calls: list[str] = []
        self.reading = True

    def write(self, data: Any) -> None:
        self.sent += data
        self.calls.append("write")

    def close(self) -> None:
        self.calls.append("close")

    def abort(self) -> None:
        self.calls.append("abort")

    def pause_reading(self) -> None:
        self.reading = False

    def resume_reading(self) -> None:
        self.reading = True

    @property
    def closed(self) -> bool:
        return "close" in self.calls or "abort" in self.calls


class _App(asyncio.Protocol):
    """The plaintext side: what reached it."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.eofs = 0
        self.lost: list[BaseException | None] = []
        self.flow: list[str] = []

    def data_received(self, data: bytes) -> None:
        self.data += data

    def eof_received(self) -> bool:
        self.eofs += 1
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost.append(exc)

    def pause_writing(self) -> None:
        self.flow.append("pause")

    def resume_writing(self) -> None:
        self.flow.append("resume")


def _feed(layer: TlsBioTransport, data: bytes, rng: random.Random | None = None) -> None:
    """`data` into `layer` as its plain transport would give it: in one piece, or cut at random."""
    while data:
        size = len(data) if rng is None else rng.randint(1, len(data))
        buffer = layer.get_buffer(-1)
        size = min(size, len(buffer))
        buffer[:size] = data[:size]
        data = data[size:]
        layer.buffer_updated(size)


class _Pair:
    """A client and a server layer, each on a `_Wire`; `pump` carries the bytes across."""

    def __init__(self, client: ssl.SSLContext, server: ssl.SSLContext) -> None:
        self.client_app, self.server_app = _App(), _App()
        self.client = TlsBioTransport(client, self.client_app, server_hostname="127.0.0.1")
        self.server = TlsBioTransport(server, self.server_app, server_side=True)
        self.client_wire, self.server_wire = _Wire(), _Wire()
        self.server.connection_made(self.server_wire)
        self.client.connection_made(self.client_wire)

    def pump(self, rng: random.Random | None = None) -> None:
        for _ in range(20):  # a handshake takes a few flights; each flight one turn
            moved = False
            for wire, layer in ((self.client_wire, self.server), (self.server_wire, self.client)):
                if wire.sent:
                    data, wire.sent = bytes(wire.sent), bytearray()
                    _feed(layer, data, rng)
                    moved = True
            if not moved:
                return
        raise AssertionError("the two ends kept talking")


def _contexts(pki: dict[str, Any], who: str) -> tuple[ssl.SSLContext, ssl.SSLContext]:
    ca = pki["ca"].cafile
    client = client_tls_context(pki[who].certfile, pki[who].keyfile, ca)
    return client, server_tls_context(pki["server"].certfile, pki["server"].keyfile, ca)


async def test_records_cut_anywhere_arrive_whole_and_in_order(pki: dict[str, Any]) -> None:
    seed = int(os.environ.get("TLS_BIO_SEED", random.randrange(2**32)))
    rng = random.Random(seed)
    pair = _Pair(*_contexts(pki, "operator"))
    pair.pump(rng)
    await asyncio.wait_for(pair.client.handshake(), 1)
    await asyncio.wait_for(pair.server.handshake(), 1)
    assert (pair.client.state, pair.server.state) == ("open", "open")
    sent: dict[str, bytearray] = {"client": bytearray(), "server": bytearray()}
    for _ in range(40):
        side = rng.choice(("client", "server"))
        data = rng.randbytes(rng.choice((1, 7, 260, rng.randint(1, 40000))))
        (pair.client if side == "client" else pair.server).write(data)
        sent[side] += data
        if rng.random() < 0.5:
            pair.pump(rng)
    pair.pump(rng)
    assert pair.server_app.data == sent["client"], f"seed {seed}"
    assert pair.client_app.data == sent["server"], f"seed {seed}"
    assert pair.server.get_extra_info("ssl_object").getpeercert(binary_form=True)
    before = len(pair.server_wire.calls)
    pair.client.close()  # close_notify
    assert pair.client.state == "closed"
    assert pair.client_wire.calls[-2:] == ["write", "close"], f"seed {seed}"
    pair.pump(rng)
    assert pair.server_app.eofs == 1, f"seed {seed}"
    assert pair.server.state == "closed"
    assert pair.server_wire.calls[before:] == ["write", "close"], "close_notify back, then closed"
    pair.server.connection_lost(None)
    assert pair.server_app.lost == [None]
    assert pair.client_app.lost == [], "the client app is told by its own transport's end"


async def test_records_that_come_in_one_receive_are_all_handed_on(pki: dict[str, Any]) -> None:
    pair = _Pair(*_contexts(pki, "operator"))
    # The server's flight, then the client's Finished and its first two requests in one piece.
    _feed(pair.server, bytes(pair.client_wire.sent))
    pair.client_wire.sent.clear()
    _feed(pair.client, bytes(pair.server_wire.sent))
    pair.server_wire.sent.clear()
    await asyncio.wait_for(pair.client.handshake(), 1)
    pair.client.write(b"first")
    pair.client.write(b"second")
    assert pair.client_wire.calls.count("write") >= 3, "Finished, then a write per request"
    _feed(pair.server, bytes(pair.client_wire.sent))
    await asyncio.wait_for(pair.server.handshake(), 1)
    assert pair.server_app.data == b"firstsecond"
    pair.server.write(b"one")
    pair.server.write(b"two")
    pair.server.write(b"three")
    pair.client_wire.sent.clear()
    _feed(pair.client, bytes(pair.server_wire.sent))  # session tickets and three records
    assert pair.client_app.data == b"onetwothree"


@pytest.mark.parametrize(
    ("who", "reason", "words"),
    [
        ("expired", "SSLV3_ALERT_CERTIFICATE_EXPIRED", "it has expired"),
        ("untrusted", "TLSV1_ALERT_UNKNOWN_CA", "it was signed by a CA the server does not trust"),
    ],
)
async def test_a_refused_handshake_sends_its_alert_before_closing(
    pki: dict[str, Any], who: str, reason: str, words: str
) -> None:
    pair = _Pair(*_contexts(pki, who))
    pair.pump()
    with pytest.raises(ssl.SSLCertVerificationError):
        await asyncio.wait_for(pair.server.handshake(), 1)
    assert pair.server_wire.calls[-2:] == ["write", "close"], "the alert, then the close"
    assert pair.server_app.lost == [], "the server's app never had the connection"
    await asyncio.wait_for(pair.client.handshake(), 1)  # TLS 1.3: the client finished first
    (error,) = pair.client_app.lost  # the alert, read with the next records
    assert isinstance(error, ssl.SSLError)
    assert error.reason == reason
    assert str(server_refusal("tls://x", error)) == (
        f"tls://x: the server refused this client's certificate: {words}"
    )
    assert pair.client.state == "closed"
    assert pair.client_wire.closed


async def test_a_plaintext_flood_is_refused_and_dropped_unread(pki: dict[str, Any]) -> None:
    app = _App()
    layer = TlsBioTransport(_contexts(pki, "operator")[1], app, server_side=True)
    wire = _Wire()
    layer.connection_made(wire)
    request = bytes.fromhex("0001 0000 0006 01 03 0000 0001")
    _feed(layer, request * 5000)  # 60,000 bytes in one receive
    with pytest.raises(ssl.SSLError) as caught:
        await asyncio.wait_for(layer.handshake(), 1)
    assert caught.value.reason == "WRONG_VERSION_NUMBER"
    assert layer.state == "closed"
    assert wire.closed
    for _ in range(200):  # 12 MB more, as a flood that goes on until the close
        _feed(layer, request * 5000)
    assert layer._incoming.pending <= len(layer.get_buffer(-1)), "bounded: one receive at most"
    assert app.data == b""
    assert app.lost == []


async def test_an_end_of_stream_in_the_handshake_fails_it_and_after_it_ends_the_stream(
    pki: dict[str, Any],
) -> None:
    app = _App()
    layer = TlsBioTransport(_contexts(pki, "operator")[0], app, server_hostname="127.0.0.1")
    layer.connection_made(_Wire())
    assert layer.eof_received() is False
    with pytest.raises(ConnectionResetError, match="during the handshake"):
        await asyncio.wait_for(layer.handshake(), 1)
    assert app.eofs == 0
    assert app.lost == []

    pair = _Pair(*_contexts(pki, "operator"))
    pair.pump()
    await asyncio.wait_for(pair.server.handshake(), 1)
    pair.server.eof_received()  # no close_notify: taken as an end all the same
    assert pair.server_app.eofs == 1
    assert pair.server.state == "closed"
    pair.server.connection_lost(None)
    assert pair.server_app.lost == [None]


async def test_a_handshake_out_of_time_drops_the_connection(pki: dict[str, Any]) -> None:
    layer = TlsBioTransport(_contexts(pki, "operator")[1], _App(), server_side=True)
    wire = _Wire()
    layer.connection_made(wire)
    with pytest.raises(TimeoutError):
        await asyncio.wait_for(layer.handshake(), 0.01)
    assert wire.calls == ["abort"]
    assert layer.state == "closed"


async def test_a_close_in_the_handshake_ends_the_wait_for_it(pki: dict[str, Any]) -> None:
    app = _App()
    layer = TlsBioTransport(_contexts(pki, "operator")[1], app, server_side=True)
    wire = _Wire()
    layer.connection_made(wire)
    waiting = asyncio.ensure_future(layer.handshake())
    await asyncio.sleep(0)
    layer.close()
    with pytest.raises(ConnectionAbortedError, match="closed during the handshake"):
        await asyncio.wait_for(waiting, 1)
    assert wire.calls == ["close"]
    layer.connection_lost(None)
    assert app.lost == [], "the app never had the connection"


async def test_back_pressure_passes_through_both_ways(pki: dict[str, Any]) -> None:
    """The plain transport's full write buffer reaches the app (the stream's write gate), and
    the app's pause of reading reaches the plain transport (a server's unread requests)."""
    pair = _Pair(*_contexts(pki, "operator"))
    pair.pump()
    pair.server.pause_writing()
    pair.server.resume_writing()
    assert pair.server_app.flow == ["pause", "resume"]
    pair.server.pause_reading()
    assert not pair.server_wire.reading
    pair.server.resume_reading()
    assert pair.server_wire.reading


async def test_writing_before_the_handshake_is_refused(pki: dict[str, Any]) -> None:
    layer = TlsBioTransport(_contexts(pki, "operator")[0], _App(), server_hostname="127.0.0.1")
    layer.connection_made(_Wire())
    with pytest.raises(RuntimeError, match="cannot write while handshaking"):
        layer.write(b"early")
    layer.close()
    with pytest.raises(RuntimeError, match="cannot write while closed"):
        layer.write(b"late")


async def test_the_state_table_refuses_a_move_it_does_not_have(pki: dict[str, Any]) -> None:
    layer = TlsBioTransport(_contexts(pki, "operator")[0], _App(), server_hostname="127.0.0.1")
    assert (_State.CLOSED, _Event.HANDSHAKE_DONE) not in _NEXT
    assert {state for state, _ in _NEXT} == set(_State)
    layer.close()
    with pytest.raises(RuntimeError, match="no move from closed on the handshake finished"):
        layer._move(_Event.HANDSHAKE_DONE)


async def test_a_client_asking_to_renegotiate_is_refused(pki: dict[str, Any]) -> None:
    """OpenSSL's own client (TLS 1.2, the last version with renegotiation) asks for it once the
    session is up; the server refuses, and serves the next client as usual."""
    operator = pki["operator"]
    async with tls_server(pki) as server:
        client = await asyncio.create_subprocess_exec(
            "openssl", "s_client", "-tls1_2", "-connect", f"127.0.0.1:{server.port}",
            "-cert", str(operator.certfile), "-key", str(operator.keyfile),
            "-CAfile", str(pki["ca"].cafile),
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT,
        )  # fmt: skip
        assert client.stdin is not None
        assert client.stdout is not None
        said = b""
        async with asyncio.timeout(10):
            while b"Verify return code" not in said:  # the session is up
                line = await client.stdout.readline()
                assert line, said.decode(errors="replace")
                said += line
            client.stdin.write(b"R\n")  # s_client's command: renegotiate
            said += await client.stdout.read()  # until the server ends the session
            await client.wait()
        assert b"RENEGOTIATING" in said
        assert b"no renegotiation" in said, said.decode(errors="replace")[-500:]
        async with tls_master(pki, server, "operator") as master:
            assert await master.read_holding_registers(1, 0, 2) == [1, 2]


@pytest.mark.parametrize("pushed", [True, False])
async def test_a_handshake_left_unfinished_is_closed_in_time(
    pki: dict[str, Any],
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    pushed: bool,
) -> None:
    """A slow client (half a record header, then nothing) holds a connection no longer than the
    handshake's time bound, on the pushed path and on anyio's."""
    monkeypatch.setattr(tls_server_module, "HANDSHAKE_TIMEOUT", 0.3)
    monkeypatch.setattr(push_server_module, "loop_pushes", lambda: pushed)
    caplog.set_level(logging.WARNING, logger="aiortu")
    async with tls_server(pki) as server:
        reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
        writer.write(b"\x16\x03")  # the start of a handshake record, and no more
        loop = asyncio.get_running_loop()
        started = loop.time()
        async with asyncio.timeout(5):
            with contextlib.suppress(ConnectionError):
                assert await reader.read() == b""  # the server closed it
        assert loop.time() - started < 3
        writer.close()
        assert server.handshake_failures == 1
    (line,) = [
        r.getMessage() for r in caplog.records if "closed the connection of" in r.getMessage()
    ]
    assert line.endswith(": the TLS handshake did not finish in time"), line
