"""Modbus UDP and Modbus/TCP Security against pymodbus, both ways: its clients against
aiortu's servers in this process, aiortu's master against its servers in a process of their
own."""

from __future__ import annotations

import ssl
from pathlib import Path
from typing import Any

import pytest

import aiortu
from tests.pymodbus_server import HOLDING_REGISTERS
from tests.transport import pymodbus_peers
from tests.transport.certificates import Authority

pymodbus_client = pytest.importorskip("pymodbus.client")

pytestmark = [pytest.mark.interop, pytest.mark.timeout(60)]

UNIT = {"device_id": 1}


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: [10, 20, 30, 0, 0]}, coils={0: [0] * 16})


async def _reads_and_writes(client: Any) -> None:
    """What a pymodbus client does against aiortu's unit 1 of _store()."""
    assert (await client.read_holding_registers(0, count=3, **UNIT)).registers == [10, 20, 30]
    assert not (await client.write_registers(3, [7, 8], **UNIT)).isError()
    assert (await client.read_holding_registers(2, count=3, **UNIT)).registers == [30, 7, 8]
    assert not (await client.write_coil(5, True, **UNIT)).isError()
    assert (await client.read_coils(4, count=3, **UNIT)).bits[:3] == [False, True, False]
    missing = await client.read_holding_registers(100, count=1, **UNIT)
    assert missing.isError()
    assert missing.exception_code == 2


async def test_pymodbus_udp_client_against_aiortu() -> None:
    async with aiortu.serve("udp://127.0.0.1:0", {1: _store()}) as server:
        client = pymodbus_client.AsyncModbusUdpClient("127.0.0.1", port=server.port, timeout=2)
        await client.connect()
        try:
            await _reads_and_writes(client)
        finally:
            client.close()
        assert server.datagrams.refused == 0


async def test_aiortu_master_against_pymodbus_udp_server() -> None:
    with pymodbus_peers.running("udp") as port:
        async with aiortu.open_master(f"udp://127.0.0.1:{port}", timeout=2.0) as master:
            assert await master.read_holding_registers(1, 0, 3) == HOLDING_REGISTERS[:3]
            await master.write_registers(1, 30, [5, 6])
            assert await master.read_holding_registers(1, 30, 2) == [5, 6]
            counters = master.link.stream.counters
            assert (counters.strangers, counters.refused, counters.dropped) == (0, 0, 0)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    ca = Authority(tmp_path_factory.mktemp("interop-pki"))
    return {
        "ca": ca,
        "server": ca.issue("server", server=True),
        "operator": ca.issue("operator", role="operator"),
        "viewer": ca.issue("viewer", role="viewer"),
    }


def _client_context(pki: dict[str, Any], who: str) -> ssl.SSLContext:
    context = ssl.create_default_context(cafile=str(pki["ca"].cafile))
    context.load_cert_chain(pki[who].certfile, pki[who].keyfile)
    return context


async def test_pymodbus_tls_client_against_aiortu_with_roles(
    pki: dict[str, Any], tmp_path: Path
) -> None:
    rules = tmp_path / "rules.toml"
    rules.write_text(
        "[roles.operator]\nfunction_codes = [1, 3, 5, 16]\n"
        "[roles.viewer]\nfunction_codes = [1, 3, 5, 16]\nread_only = true\n",
        encoding="utf-8",
    )
    server_files = {"certfile": pki["server"].certfile, "keyfile": pki["server"].keyfile}
    async with aiortu.serve(
        "tls://127.0.0.1:0", {1: _store()}, cafile=pki["ca"].cafile, rules=rules, **server_files
    ) as server:
        operator = pymodbus_client.AsyncModbusTlsClient(
            "127.0.0.1", port=server.port, sslctx=_client_context(pki, "operator"), timeout=2
        )
        assert await operator.connect()
        try:
            await _reads_and_writes(operator)
        finally:
            operator.close()
        viewer = pymodbus_client.AsyncModbusTlsClient(
            "127.0.0.1", port=server.port, sslctx=_client_context(pki, "viewer"), timeout=2
        )
        assert await viewer.connect()
        try:
            assert (await viewer.read_holding_registers(0, count=1, **UNIT)).registers == [10]
            refused = await viewer.write_register(0, 99, **UNIT)
            assert refused.isError()
            assert refused.exception_code == 1
            refused = await viewer.write_registers(0, [99], **UNIT)
            assert refused.exception_code == 1
            assert (await viewer.read_holding_registers(0, count=1, **UNIT)).registers == [10]
        finally:
            viewer.close()
        assert server.denied == 2


async def test_aiortu_master_against_pymodbus_tls_server(pki: dict[str, Any]) -> None:
    server = pki["server"]
    with pymodbus_peers.running(
        "tls", str(server.certfile), str(server.keyfile), str(pki["ca"].cafile)
    ) as port:
        async with aiortu.open_master(
            f"tls://127.0.0.1:{port}",
            certfile=pki["operator"].certfile,
            keyfile=pki["operator"].keyfile,
            cafile=pki["ca"].cafile,
            timeout=2.0,
        ) as master:
            assert await master.read_holding_registers(1, 0, 3) == HOLDING_REGISTERS[:3]
            await master.write_register(1, 31, 0xBEEF)
            assert await master.read_holding_registers(1, 31, 1) == [0xBEEF]
