"""RTU over TCP against an anyio listener on the loopback interface."""

from __future__ import annotations

import contextlib
import socket
from collections.abc import AsyncIterator

import anyio
import pytest
from anyio.abc import SocketAttribute, SocketListener, SocketStream

from aiortu.errors import InvalidValue, PortNotFound
from aiortu.transport import open_rtu_over_tcp
from aiortu.transport._tcp import format_tcp_url

REQUEST = bytes.fromhex("1103006b00037687")
REPLY = bytes.fromhex("1103060ae10000000000")


async def device_server(listener: SocketListener) -> None:
    """Answer REQUEST with REPLY on each connection, as a device behind a server would."""

    async def handle(client: SocketStream) -> None:
        async with client:
            received = b""
            while len(received) < len(REQUEST):
                received += await client.receive()
            if received == REQUEST:
                await client.send(REPLY)
            else:
                await client.aclose()

    await listener.serve(handle)


@contextlib.asynccontextmanager
async def running_server(host: str = "127.0.0.1") -> AsyncIterator[int]:
    """A device server on a free loopback port; yields the port.

    A context manager rather than a fixture: the task group must be left by the task
    that entered it, and pytest-asyncio tears fixtures down in another task.
    """
    listener = await anyio.create_tcp_listener(local_host=host)
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(device_server, listener)
        yield listener.extra(SocketAttribute.local_port)
        tg.cancel_scope.cancel()


async def receive_forever(stream: SocketStream) -> None:
    while True:
        await stream.receive()


def free_port() -> int:
    """A loopback port nothing listens on (bound, then released)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


async def test_frames_travel_both_ways() -> None:
    async with running_server() as port, await open_rtu_over_tcp("127.0.0.1", port) as stream:
        await stream.send(REQUEST)
        received = b""
        with anyio.fail_after(2):
            while len(received) < len(REPLY):
                received += await stream.receive()
        assert received == REPLY


async def test_nagle_is_off() -> None:
    async with running_server() as port, await open_rtu_over_tcp("127.0.0.1", port) as stream:
        sock = stream.extra(SocketAttribute.raw_socket)
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)


async def test_server_closing_is_end_of_stream() -> None:
    async with running_server() as port, await open_rtu_over_tcp("127.0.0.1", port) as stream:
        await stream.send(b"\x00" * len(REQUEST))  # not the request: the server hangs up
        with anyio.fail_after(2), pytest.raises(anyio.EndOfStream):
            await receive_forever(stream)


async def test_refused_port_is_port_not_found() -> None:
    port = free_port()
    with pytest.raises(PortNotFound, match=f"rtu\\+tcp://127.0.0.1:{port}: connection refused"):
        await open_rtu_over_tcp("127.0.0.1", port)


async def test_unknown_host_is_port_not_found(monkeypatch: pytest.MonkeyPatch) -> None:
    # No name lookups leave the machine: the resolver's failure is simulated.
    async def failing_connect(*args: object, **kwargs: object) -> SocketStream:
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(anyio, "connect_tcp", failing_connect)
    with pytest.raises(PortNotFound, match="rtu\\+tcp://no-such-server:502: unknown host"):
        await open_rtu_over_tcp("no-such-server", 502)


async def test_timeout_is_port_not_found(monkeypatch: pytest.MonkeyPatch) -> None:
    async def silent_connect(*args: object, **kwargs: object) -> SocketStream:
        await anyio.sleep_forever()
        raise AssertionError("unreachable")

    monkeypatch.setattr(anyio, "connect_tcp", silent_connect)
    with anyio.fail_after(2), pytest.raises(PortNotFound, match=r"no answer within 0\.1 s"):
        await open_rtu_over_tcp("127.0.0.1", 5020, connect_timeout=0.1)


@pytest.mark.parametrize("port", [0, 65536, -1, True])
async def test_bad_port_number(port: int) -> None:
    with pytest.raises(InvalidValue, match="port"):
        await open_rtu_over_tcp("127.0.0.1", port)


async def test_bad_timeout() -> None:
    with pytest.raises(InvalidValue, match="connect_timeout"):
        await open_rtu_over_tcp("127.0.0.1", 5020, connect_timeout=0)


def test_format_tcp_url() -> None:
    assert format_tcp_url("gateway.local", 4001) == "rtu+tcp://gateway.local:4001"
    assert format_tcp_url("::1", 5020) == "rtu+tcp://[::1]:5020"
