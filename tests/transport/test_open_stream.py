"""Port names: URL parsing, and open_stream() dispatching to the right transport."""

from __future__ import annotations

import socket

import anyio
import pytest
from anyio.abc import SocketAttribute, SocketStream
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue, PortNotFound
from aiortu.transport import (
    ListenAddress,
    ModbusTcpAddress,
    ModbusTcpCounters,
    PortAddress,
    PushConnectionStream,
    SerialAddress,
    SerialStream,
    TcpAddress,
    open_stream,
    parse_listen_url,
    parse_port_url,
)
from tests.transport.ptys import LINE, open_pty, read_master


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("/dev/ttyUSB0", SerialAddress("/dev/ttyUSB0")),
        (
            "/dev/serial/by-id/usb-FTDI_FT232R-if00-port0",
            SerialAddress("/dev/serial/by-id/usb-FTDI_FT232R-if00-port0"),
        ),
        ("COM3", SerialAddress("COM3")),
        ("rtu+tcp://192.168.1.50:4001", TcpAddress("192.168.1.50", 4001)),
        ("rtu+tcp://gateway.plant.local:4001/", TcpAddress("gateway.plant.local", 4001)),
        ("RTU+TCP://gw:1", TcpAddress("gw", 1)),
        ("rtu+tcp://[::1]:5020", TcpAddress("::1", 5020)),
        ("rtu+tcp://[fe80::1%eth0]:502", TcpAddress("fe80::1%eth0", 502)),
        ("rtu+tcp://localhost:65535", TcpAddress("localhost", 65535)),
        ("tcp://plc.local:502", ModbusTcpAddress("plc.local", 502)),
        ("TCP://[::1]:1502/", ModbusTcpAddress("::1", 1502)),
    ],
)
def test_parse_valid(text: str, expected: PortAddress) -> None:
    assert parse_port_url(text) == expected


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("", "empty"),
        ("   ", "empty"),
        ("mbaps://host:802", "unknown scheme 'mbaps'"),
        ("tcp://host:0", "outside 1..65535"),
        ("tcp://::1:502", "tcp://[::1]:5020"),
        ("socket://host:502", "unknown scheme"),
        ("rtu+udp://host:502", "unknown scheme"),
        ("rtu+tcp://host", "port number is missing"),
        ("rtu+tcp://host:", "port is missing"),
        ("rtu+tcp://:502", "host is missing"),
        ("rtu+tcp://host:0", "outside 1..65535"),
        ("rtu+tcp://host:65536", "outside 1..65535"),
        ("rtu+tcp://host:50x", "not a number"),
        ("rtu+tcp://host:+502", "not a number"),
        ("rtu+tcp://host:502/path", "no path"),
        ("rtu+tcp://host:502?x=1", "no path, query"),
        ("rtu+tcp://user@host:502", "no user name"),
        ("rtu+tcp://::1:5020", "IPv6 address in brackets"),
        ("rtu+tcp://[::1]", "port number is missing"),
        ("rtu+tcp://[::1:5020", "closing ']'"),
        ("rtu+tcp://[not-v6]:5020", "not an IPv6 address"),
        ("rtu+tcp://[::1]5020", "expected ':port'"),
    ],
)
def test_parse_invalid(text: str, reason: str) -> None:
    with pytest.raises(InvalidValue, match="port") as info:
        parse_port_url(text)
    assert reason in str(info.value)
    assert info.value.value == text


def test_an_unknown_scheme_is_one_sentence_listing_the_forms_once() -> None:
    with pytest.raises(InvalidValue) as info:
        parse_port_url("socket://10.0.0.7:502")
    assert str(info.value) == (
        "port must be a serial device path, rtu+tcp://host:port, ascii+tcp://host:port, "
        "tcp://host:port, udp://host:port or tls://host:port, not 'socket://10.0.0.7:502': "
        "unknown scheme 'socket'"
    )


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("tcp://0.0.0.0:1502", ListenAddress("tcp", "0.0.0.0", 1502)),
        ("tcp://127.0.0.1:0", ListenAddress("tcp", "127.0.0.1", 0)),
        ("RTU+TCP://[::]:5020", ListenAddress("rtu+tcp", "::", 5020)),
    ],
)
def test_parse_listen_url(text: str, expected: ListenAddress) -> None:
    assert parse_listen_url(text) == expected
    assert parse_listen_url(str(expected)) == expected


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("/dev/ttyUSB0", "listens on a tcp:// or rtu+tcp:// URL"),
        ("udp://0.0.0.0:502", "listens on a tcp:// or rtu+tcp:// URL"),
        ("tcp://0.0.0.0", "port number is missing: tcp://host:port"),
        ("tcp://0.0.0.0:65536", "outside 0..65535"),
    ],
)
def test_parse_listen_url_refuses(text: str, reason: str) -> None:
    with pytest.raises(InvalidValue) as info:
        parse_listen_url(text)
    assert reason in str(info.value)


async def test_modbus_tcp_opens_a_stream_of_whole_frames() -> None:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(SocketAttribute.local_port)
    async with listener:
        counters = ModbusTcpCounters(next_transaction_id=7)
        stream = await open_stream(f"tcp://127.0.0.1:{port}", counters=counters)
        async with stream:
            assert isinstance(stream, PushConnectionStream)  # asyncio: pushed
            assert stream.counters is counters
            assert stream.whole_frames
    with pytest.raises(TypeError, match="Modbus TCP takes no option rs485"):
        await open_stream(f"tcp://127.0.0.1:{port}", rs485=True)


hosts = st.one_of(
    st.from_regex(r"[a-z0-9]([a-z0-9-]{0,20}[a-z0-9])?(\.[a-z0-9]{1,10}){0,3}", fullmatch=True),
    st.ip_addresses(v=4).map(str),
    st.ip_addresses(v=6).map(str),
)


@given(host=hosts, port=st.integers(1, 65535))
def test_tcp_address_round_trips(host: str, port: int) -> None:
    address = TcpAddress(host, port)
    assert parse_port_url(str(address)) == address


@given(text=st.text())
def test_any_text_parses_or_is_invalid(text: str) -> None:
    try:
        address = parse_port_url(text)
    except InvalidValue as exc:
        error = exc
    else:
        if isinstance(address, SerialAddress):
            assert address.path == text
            assert "://" not in text
        else:
            assert 1 <= address.port <= 65535
        return
    assert error.value == text
    assert repr(text) in str(error)


@given(path=st.text(min_size=1).filter(lambda t: t.strip() and "://" not in t))
def test_anything_without_a_scheme_is_a_device_path(path: str) -> None:
    assert parse_port_url(path) == SerialAddress(path)


async def test_open_stream_serial() -> None:
    with open_pty() as pty:
        stream = await open_stream(pty.path, LINE, local_echo=True)
        async with stream:
            assert isinstance(stream, SerialStream)
            assert stream.settings == LINE
            assert stream.echo is not None
            await stream.send(b"\x01\x02")
            assert await read_master(pty, 2) == b"\x01\x02"


async def echo_server(client: SocketStream) -> None:
    async with client:
        async for chunk in client:
            await client.send(chunk)


@pytest.mark.parametrize(("bind", "url_host"), [("127.0.0.1", "127.0.0.1"), ("::1", "[::1]")])
async def test_open_stream_tcp(bind: str, url_host: str) -> None:
    try:
        listener = await anyio.create_tcp_listener(local_host=bind)
    except OSError:
        pytest.skip(f"no loopback on {bind}")
    async with listener, anyio.create_task_group() as tg:
        tg.start_soon(listener.serve, echo_server)
        port = listener.extra(SocketAttribute.local_port)
        stream = await open_stream(f"rtu+tcp://{url_host}:{port}", connect_timeout=2)
        async with stream:
            assert stream.extra(SocketAttribute.family) in (socket.AF_INET, socket.AF_INET6)
            await stream.send(b"\x11\x03")
            with anyio.fail_after(2):
                assert await stream.receive() == b"\x11\x03"
        tg.cancel_scope.cancel()


async def test_open_stream_refused_tcp() -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    with pytest.raises(PortNotFound, match="refused"):
        await open_stream(f"rtu+tcp://127.0.0.1:{port}")


async def test_open_stream_rejects_bad_urls_before_any_io() -> None:
    with pytest.raises(InvalidValue, match="port number is missing"):
        await open_stream("rtu+tcp://127.0.0.1")
    with pytest.raises(InvalidValue, match="unknown scheme"):
        await open_stream("modbus://127.0.0.1:502")


async def test_open_stream_rejects_options_of_the_other_transport() -> None:
    with pytest.raises(TypeError, match="takes no option local_echo"):
        await open_stream("rtu+tcp://127.0.0.1:5020", local_echo=True)
    with open_pty() as pty, pytest.raises(TypeError, match="takes no option connect_timeout"):
        await open_stream(pty.path, LineSettings(9600, parity="N"), connect_timeout=1)
