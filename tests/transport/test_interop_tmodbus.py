"""Modbus UDP, Modbus/TCP Security and Modbus ASCII against tmodbus 1.1.0, both ways, its side
in a process of its own, from a venv of its own (see tests/peers/venvs.py)."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

import aiortu
from tests.peers.venvs import tmodbus_python
from tests.transport.certificates import Authority

pytestmark = [pytest.mark.interop, pytest.mark.timeout(120)]

PEER = str(Path(__file__).with_name("tmodbus_peer.py"))


@pytest.fixture(scope="module")
def tmodbus() -> str:
    """The Python of a venv with tmodbus 1.1.0, made when missing."""
    return tmodbus_python()


@contextmanager
def tmodbus_server(python: str, *argv: str) -> Iterator[int]:
    server = subprocess.Popen(
        [python, PEER, "server", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert server.stdout is not None
        line = server.stdout.readline().split() or ["(nothing)"]
        if line[0] != "ready":
            raise RuntimeError(f"tmodbus's server did not start: {server.stderr.read()}")
        yield int(line[1])
    finally:
        server.terminate()
        server.wait(timeout=10)


async def tmodbus_client(python: str, *argv: str) -> list[str]:
    """Run tmodbus's client script; its output lines."""
    import anyio

    done = await anyio.run_process(
        [python, PEER, "client", *argv], check=False, stdin=subprocess.DEVNULL
    )
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    return done.stdout.decode().splitlines()


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: [10, 20, 30, 0, 0]})


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    ca = Authority(tmp_path_factory.mktemp("tmodbus-pki"))
    return {
        "ca": ca,
        "server": ca.issue("server", server=True),
        "operator": ca.issue("operator", role="operator"),
        "viewer": ca.issue("viewer", role="viewer"),
    }


async def test_tmodbus_udp_client_against_aiortu(tmodbus: str) -> None:
    store = _store()
    async with aiortu.serve("udp://127.0.0.1:0", {1: store}) as server:
        lines = await tmodbus_client(tmodbus, "udp", str(server.port))
    assert lines == ["read [10, 20, 30]", "read [30, 7, 8]", "written"]
    assert server.datagrams.refused == 0


async def test_aiortu_master_against_tmodbus_udp_server(tmodbus: str) -> None:
    with tmodbus_server(tmodbus, "udp") as port:
        async with aiortu.open_master(f"udp://127.0.0.1:{port}", timeout=3.0) as master:
            assert await master.read_holding_registers(1, 0, 3) == [0, 1, 2]
            await master.write_registers(1, 3, [7, 8])
            assert await master.read_holding_registers(1, 2, 3) == [2, 7, 8]


async def test_tmodbus_tls_clients_against_aiortu_with_roles(
    tmodbus: str, pki: dict[str, Any], tmp_path: Path
) -> None:
    rules = tmp_path / "rules.toml"
    rules.write_text(
        "[roles.operator]\nfunction_codes = [3, 6, 16]\n"
        "[roles.viewer]\nfunction_codes = [3, 6, 16]\nunits = [1]\naddresses = [[0, 4]]\n"
        "read_only = true\n",
        encoding="utf-8",
    )
    files = {"certfile": pki["server"].certfile, "keyfile": pki["server"].keyfile}
    async with aiortu.serve(
        "tls://127.0.0.1:0", {1: _store()}, cafile=pki["ca"].cafile, rules=rules, **files
    ) as server:

        def client(who: str) -> list[str]:
            return [str(pki[who].certfile), str(pki[who].keyfile), str(pki["ca"].cafile)]

        operator = await tmodbus_client(tmodbus, "tls", str(server.port), *client("operator"))
        assert operator == ["read [10, 20, 30]", "read [30, 7, 8]", "written"]
        # The viewer may read; its first write (16 at 3) is refused, so its script stops there.
        done = await _viewer(tmodbus, server.port, client("viewer"))
        assert done[0] == "read [99, 20, 30]"
        assert "IllegalFunctionError" in done[-1] or "0x01" in done[-1]
        assert server.denied == 1


async def _viewer(python: str, port: int, files: list[str]) -> list[str]:
    import anyio

    done = await anyio.run_process(
        [python, PEER, "client", "tls", str(port), *files], check=False, stdin=subprocess.DEVNULL
    )
    assert done.returncode != 0, "the viewer's write went through"
    return [*done.stdout.decode().splitlines(), done.stderr.decode().strip().splitlines()[-1]]


async def test_aiortu_master_against_tmodbus_tls_server_with_roles(
    tmodbus: str, pki: dict[str, Any]
) -> None:
    files = [str(pki["server"].certfile), str(pki["server"].keyfile), str(pki["ca"].cafile)]
    with tmodbus_server(tmodbus, "tls", *files) as port:
        for who in ("operator", "viewer"):
            async with aiortu.open_master(
                f"tls://127.0.0.1:{port}",
                certfile=pki[who].certfile,
                keyfile=pki[who].keyfile,
                cafile=pki["ca"].cafile,
                timeout=3.0,
            ) as master:
                assert (await master.read_holding_registers(1, 0, 2))[1] == 1
                if who == "operator":
                    await master.write_register(1, 0, 5)
                    assert await master.read_holding_registers(1, 0, 1) == [5]
                else:
                    with pytest.raises(aiortu.ExceptionResponse) as caught:
                        await master.write_register(1, 0, 6)
                    assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_FUNCTION
