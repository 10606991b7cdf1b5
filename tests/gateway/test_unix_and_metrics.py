"""`unix:PATH` listeners, and the statistics per line, unit and client: printed as text and
served as Prometheus text over HTTP (fetched on 127.0.0.1, port 0, and parsed)."""

from __future__ import annotations

import os
import re
import socket
import stat
from contextlib import AsyncExitStack
from pathlib import Path

import anyio
import pytest

from aiortu.errors import InvalidValue, PortBusy
from aiortu.gateway import GatewayStatistics, gateway
from tests.gateway.helpers import UNIT, TcpClient, client, line

pytestmark = pytest.mark.timeout(30)

_SAMPLE = re.compile(r"^(\w+)\{(.*)\} (\d+)$")


async def test_a_unix_socket_serves_modbus_tcp_and_is_removed_after(tmp_path: Path) -> None:
    path = str(tmp_path / "gw.sock")
    async with line(listen=(f"unix:{path}",)) as bench:
        assert bench.gateway.unix_paths == [path]
        async with await anyio.connect_unix(path) as stream:
            tcp = TcpClient(stream)
            assert await tcp.request("03 0000 0002", transaction_id=9) == "03 04 12 34 AB CD"
        assert bench.gateway.statistics.clients["unix"].requests == 1
    assert not await anyio.Path(path).exists()


async def test_a_stale_socket_file_is_replaced_and_a_live_one_refused(tmp_path: Path) -> None:
    path = str(tmp_path / "gw.sock")
    with socket.socket(socket.AF_UNIX) as stale:
        stale.bind(path)  # bound, never listening: what a killed gateway leaves
    assert stat.S_ISSOCK(os.stat(path).st_mode)
    async with line(listen=(f"unix:{path}",)) as bench:
        with pytest.raises(PortBusy, match="a program listens on that socket"):
            async with gateway(bench.master, [f"unix:{path}"]):
                pass
        async with await anyio.connect_unix(path) as stream:
            assert await TcpClient(stream).request("03 0000 0001") == "03 02 12 34"
        assert bench.gateway.counters.requests == 1


async def test_unix_without_a_path_is_refused() -> None:
    async with line() as bench:
        with pytest.raises(InvalidValue, match="the socket path is missing"):
            async with gateway(bench.master, ["unix:"]):
                pass


async def _get(address: tuple[str, int], path: str) -> tuple[str, str]:
    async with await anyio.connect_tcp(*address) as stream:
        await stream.send(f"GET {path} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
        data = b""
        with anyio.fail_after(5):
            try:
                while True:
                    data += await stream.receive()
            except anyio.EndOfStream:
                pass
    head, _, body = data.decode().partition("\r\n\r\n")
    return head, body


def _samples(body: str) -> dict[tuple[str, str], int]:
    samples = {}
    for text in body.splitlines():
        if text.startswith("#"):
            assert text.startswith(("# HELP aiortu_gateway_", "# TYPE aiortu_gateway_"))
            continue
        match = _SAMPLE.match(text)
        assert match, f"not a sample line: {text!r}"
        samples[(match[1], match[2])] = int(match[3])
    return samples


async def test_metrics_are_served_as_prometheus_text() -> None:
    url = "http://127.0.0.1:0/metrics"
    async with line(metrics=url, cache_ms=60_000) as bench, client(bench.gateway) as tcp:
        for _ in range(3):
            await tcp.request("03 0000 0001")
        await tcp.request("03 0000 0001", unit=250)
        address = bench.gateway.metrics_address
        assert address is not None
        assert address[1] != 0
        head, body = await _get(address, "/metrics")
        assert head.startswith("HTTP/1.1 200 OK")
        assert "Content-Type: text/plain; version=0.0.4" in head
        samples = _samples(body)
        unit = f'line="line",unit="{UNIT}"'
        assert samples[("aiortu_gateway_unit_requests_total", unit)] == 3
        assert samples[("aiortu_gateway_unit_replies_total", unit)] == 3
        assert samples[("aiortu_gateway_line_cache_hits_total", 'line="line"')] == 2
        assert samples[("aiortu_gateway_line_transactions_total", 'line="line"')] == 1
        client_labels = 'client="127.0.0.1"'
        assert samples[("aiortu_gateway_client_requests_total", client_labels)] == 4
        assert samples[("aiortu_gateway_client_replies_total", client_labels)] == 4
        assert samples[("aiortu_gateway_client_connections_total", client_labels)] == 1
        head, _ = await _get(address, "/other")
        assert head.startswith("HTTP/1.1 404")


def test_the_summary_has_a_line_per_line_unit_and_client() -> None:
    stats = GatewayStatistics()
    stats.line("/dev/ttyUSB0").transactions = 5
    stats.answered("/dev/ttyUSB0", 3, bytes.fromhex("83 0B"))
    stats.client("10.0.0.2").requests = 7
    assert list(stats.summary()) == [
        "line /dev/ttyUSB0: transactions=5 coalesced=0 cache_hits=0 broadcasts=0",
        "line /dev/ttyUSB0 unit 3: requests=0 replies=0 exceptions=0 no_response=1 no_path=0",
        "client 10.0.0.2: connections=0 requests=7 replies=0 refused=0",
    ]


@pytest.mark.parametrize("url", ["ftp://127.0.0.1:1/metrics", "http://127.0.0.1/metrics"])
async def test_a_bad_metrics_url_is_refused(url: str) -> None:
    async with line() as bench:
        with pytest.raises(InvalidValue, match="metrics"):
            async with gateway(bench.master, [], metrics=url):
                pass


async def test_the_metrics_listener_has_a_connection_cap_of_its_own() -> None:
    from aiortu.gateway._metrics import MAX_METRICS_CONNECTIONS

    async with line(metrics="http://127.0.0.1:0/metrics") as bench:
        address = bench.gateway.metrics_address
        assert address is not None
        async with AsyncExitStack() as stack:
            for _ in range(MAX_METRICS_CONNECTIONS):  # silent scrapers, each held 5 s
                await stack.enter_async_context(await anyio.connect_tcp(*address))
            await anyio.sleep(0.1)
            async with await anyio.connect_tcp(*address) as refused:
                with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
                    with anyio.fail_after(2):  # closed at once, not after the 5 s
                        await refused.receive()
        head, _ = await _get(address, "/metrics")
        assert head.startswith("HTTP/1.1 200 OK")
