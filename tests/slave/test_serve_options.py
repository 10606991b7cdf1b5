"""`serve()` refuses an option its listener's server does not take in one sentence, naming the
URL and what it takes, before anything is opened; the options it does take still go through."""

from __future__ import annotations

import anyio
import pytest

import aiortu
from aiortu.slave import ModbusTcpServer, ModbusTlsServer, ModbusUdpServer, RtuOverTcpServer

REFUSED = [
    ("tcp://127.0.0.1:0", {"certfile": "server.pem"}, "ModbusTcpServer", "certfile"),
    ("tls://127.0.0.1:0", {"idle_timout": 5}, "ModbusTlsServer", "idle_timout"),
    ("udp://127.0.0.1:0", {"rules": "rules.toml"}, "ModbusUdpServer", "rules"),
    ("rtu+tcp://0.0.0.0:0", {"cafile": "ca.pem"}, "RtuOverTcpServer", "cafile"),
    ("ascii+tcp://0.0.0.0:0", {"unit_aliases": {1: 2}}, "RtuOverTcpServer", "unit_aliases"),
]


@pytest.mark.parametrize(("url", "options", "server", "option"), REFUSED)
def test_an_option_the_listener_does_not_take_is_one_sentence(
    url: str, options: dict[str, object], server: str, option: str
) -> None:
    async def main() -> None:
        async with aiortu.serve(url, {1: aiortu.MemoryStore()}, **options):
            pytest.fail("served with an option its server does not take")

    with pytest.raises(TypeError) as refused:
        anyio.run(main)
    message = str(refused.value)
    assert message.startswith(f"{url}: {server} takes no option {option} (it takes ")
    assert "\n" not in message
    assert "unexpected keyword" not in message


@pytest.mark.parametrize(
    ("server", "expected"),
    [
        (ModbusTcpServer, {"idle_timeout", "max_connections", "unit_aliases"}),
        (ModbusTlsServer, {"certfile", "keyfile", "cafile", "rules", "idle_timeout"}),
        (ModbusUdpServer, {"unit_aliases", "answer_unknown_units"}),
        (RtuOverTcpServer, {"framing", "ascii_timeout", "idle_timeout"}),
    ],
)
def test_the_options_a_listener_takes_are_read_from_its_server(
    server: type, expected: set[str]
) -> None:
    # The sentence lists what the server takes: its keywords, and Modbus TCP's where it passes
    # the rest on; never what serve() gives it itself.
    async def main() -> None:
        url = {ModbusTcpServer: "tcp", ModbusTlsServer: "tls", ModbusUdpServer: "udp"}.get(
            server, "rtu+tcp"
        )
        host = "0.0.0.0" if url == "rtu+tcp" else "127.0.0.1"
        async with aiortu.serve(f"{url}://{host}:0", {1: aiortu.MemoryStore()}, bogus=1):
            pass

    with pytest.raises(TypeError) as refused:
        anyio.run(main)
    taken = set(str(refused.value).split("(it takes ")[1].rstrip(")").split(", "))
    assert expected <= taken
    assert not taken & {"units", "settings", "timing", "handlers", "trace"}


def test_an_option_the_listener_takes_still_goes_through() -> None:
    async def main() -> None:
        url = "tcp://127.0.0.1:0"
        async with aiortu.serve(url, {1: aiortu.MemoryStore()}, idle_timeout=7.5) as server:
            assert isinstance(server, ModbusTcpServer)
            assert server.idle_timeout == 7.5

    anyio.run(main)


def test_an_ascii_url_with_another_framing_is_refused() -> None:
    # The URL says ASCII: a framing that contradicts it is refused, as open_stream refuses it,
    # not served in RTU.
    async def main() -> None:
        async with aiortu.serve("ascii+tcp://0.0.0.0:0", {1: aiortu.MemoryStore()}, framing="rtu"):
            pytest.fail("served RTU on an ascii+tcp:// URL")

    with pytest.raises(aiortu.errors.InvalidValue, match="'ascii' for an ascii\\+tcp:// URL"):
        anyio.run(main)
