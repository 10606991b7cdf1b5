"""Modbus/TCP Security on asyncio's own TLS transport against the general path (anyio's TLS
stream): the connection tests of test_tls.py run again with both paths forced off (the master's
pushed stream and the server's pushed connections), and one scripted session (reads at once,
refusals by role, a plaintext server, an untrusted one) gives the same results, counters and
log lines both ways."""

from __future__ import annotations

import logging
import re
from typing import Any

import pytest

import aiortu
from aiortu.errors import PortError
from aiortu.transport import ModbusTcpStream, PushConnectionStream
from aiortu.transport import _push_server as push_server_module
from aiortu.transport import _tcp_push as tcp_push_module
from tests.transport.test_tls import (
    _client_options,
    _store,
    pki,
    test_a_bad_client_certificate_is_refused_in_one_sentence,
    test_a_certificate_without_a_role_gets_the_default_or_nothing,
    test_a_plaintext_client_on_a_tls_port_is_refused_in_one_sentence,
    test_a_read_only_role_is_refused_on_every_write_code,
    test_an_operator_reads_and_writes,
    test_the_master_refuses_an_untrusted_server,
    test_units_and_address_ranges_bound_a_role,
    tls_master,
    tls_server,
)

pytestmark = pytest.mark.timeout(60)

__all__ = (  # run again here, on the general path
    "pki",
    "test_a_bad_client_certificate_is_refused_in_one_sentence",
    "test_a_certificate_without_a_role_gets_the_default_or_nothing",
    "test_a_plaintext_client_on_a_tls_port_is_refused_in_one_sentence",
    "test_a_read_only_role_is_refused_on_every_write_code",
    "test_an_operator_reads_and_writes",
    "test_the_master_refuses_an_untrusted_server",
    "test_units_and_address_ranges_bound_a_role",
)


def _paths(monkeypatch: pytest.MonkeyPatch, pushed: bool) -> None:
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: pushed)
    monkeypatch.setattr(push_server_module, "loop_pushes", lambda: pushed)


@pytest.fixture(autouse=True)
def general_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """The general path for the master and the server, on asyncio too."""
    _paths(monkeypatch, pushed=False)


async def _session(pki: dict[str, Any], caplog: pytest.LogCaptureFixture) -> list[Any]:
    """One scripted session; what every step gave, and the warnings logged."""
    caplog.clear()
    seen: list[Any] = []
    async with tls_server(pki) as server:
        async with tls_master(pki, server, "operator") as master:
            for address in range(0, 12, 3):
                try:
                    seen.append(await master.read_holding_registers(1, address, 2))
                except aiortu.ExceptionResponse as error:
                    seen.append(("exception", error.code))
            await master.write_registers(2, 0, [9, 8, 7])
            seen.append(await master.read_holding_registers(2, 0, 4))
            seen.append(await master.read_coils(1, 0, 3))
        async with tls_master(pki, server, "viewer") as master:
            seen.append(await master.read_holding_registers(2, 1, 2))
            for _ in range(2):
                try:
                    await master.write_register(1, 0, 5)
                except aiortu.ExceptionResponse as error:
                    seen.append(("refused", error.code))
            seen.append(await master.read_holding_registers(1, 0, 1))
        seen.append((server.denied, server.counters.requests, server.handshake_failures))
        seen.append(server.machine.counters)
        for who in ("untrusted_server", "server"):
            issued = pki[who]
            plain = who == "server"
            async with aiortu.serve(
                "tcp://127.0.0.1:0" if plain else "tls://127.0.0.1:0",
                {1: _store()},
                **(
                    {}
                    if plain
                    else {
                        "certfile": issued.certfile,
                        "keyfile": issued.keyfile,
                        "cafile": pki["ca"].cafile,
                        "rules": server.rules,
                    }
                ),
            ) as other:
                try:
                    async with aiortu.open_master(
                        f"tls://127.0.0.1:{other.port}", **_client_options(pki, "operator")
                    ):
                        seen.append("connected")
                except PortError as error:
                    seen.append(str(error).split(": ", 1)[1])
    seen.append(
        [
            re.sub(r"127\.0\.0\.1:\d+", "PEER", record.getMessage())
            for record in caplog.records
            if record.levelno >= logging.WARNING
        ]
    )
    return seen


async def test_the_pushed_paths_and_the_general_path_agree(
    pki: dict[str, Any], caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    general = await _session(pki, caplog)
    _paths(monkeypatch, pushed=True)
    pushed = await _session(pki, caplog)
    # By design, one line more: the pushed master sends the untrusted server its alert (anyio's
    # TLS stream closes without it), so the server can say why.
    pushed[-1].remove(
        "Modbus/TCP Security: closed the connection of PEER: it does not trust our certificate"
        " (unknown CA)"
    )
    assert pushed == general
    assert ("refused", aiortu.ExceptionCode.ILLEGAL_FUNCTION) in pushed
    assert "the server's certificate was refused (unable to get local issuer certificate)" in (
        pushed
    )
    assert "the TLS handshake failed: it closed the connection during the TLS handshake" in (pushed)


async def test_asyncio_gets_the_pushed_paths(
    pki: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    async with tls_server(pki) as server, tls_master(pki, server, "operator") as master:
        assert isinstance(master.link.stream, ModbusTcpStream)  # forced here
        assert await master.read_holding_registers(1, 0, 2) == [1, 2]
        assert server._at_once is not None
        assert server._at_once.answered == 0
    _paths(monkeypatch, pushed=True)
    async with tls_server(pki) as server, tls_master(pki, server, "operator") as master:
        assert isinstance(master.link.stream, PushConnectionStream)
        for _ in range(3):
            assert await master.read_holding_registers(1, 0, 2) == [1, 2]
        assert server._at_once is not None
        assert server._at_once.answered == 3  # each from the read callback
        assert server.counters.requests == 3
