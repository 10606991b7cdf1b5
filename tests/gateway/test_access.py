"""Access rules per listener: a refused request gets exception 01 at once, never reaches the
line, and is counted; the rule format is the one of the TLS roles."""

from __future__ import annotations

from pathlib import Path

import anyio
import pytest

from aiortu.errors import ConfigError, InvalidValue
from aiortu.gateway import Listen, gateway
from aiortu.transport import AccessRule, RoleRules, client_tls_context, server_tls_context
from tests.gateway.helpers import UNIT, TcpClient, client, line

pytestmark = pytest.mark.anyio

READ = "0300000002"
WRITE = "0600000007"
VIEWER = RoleRules({"viewer": AccessRule(frozenset({1, 2, 3, 4}), read_only=True)}, "viewer")


async def test_a_read_only_listener_refuses_writes_with_exception_01() -> None:
    listen = (Listen("tcp://127.0.0.1:0", rules=VIEWER), "tcp://127.0.0.1:0")
    async with line(listen=listen) as served:
        seen = served.messages
        async with client(served.gateway) as reader:
            assert (await reader.request(WRITE)) == "86 01"
            assert (await reader.request("1000000001020009")) == "90 01"
            assert (await reader.request(READ)).startswith("03 04")
        assert served.messages == seen + 1  # the read only: refused writes never went out
        assert served.gateway.counters.refused_by_rules == 2
        assert served.gateway.statistics.clients["127.0.0.1"].refused == 2
        assert "aiortu_gateway_client_refused_total" in served.gateway.statistics.prometheus()
        # The other listener has no rules: the same write goes through.
        other = served.gateway.local_addresses[1][1]
        stream = await anyio.connect_tcp("127.0.0.1", other)
        async with stream:
            assert (await TcpClient(stream).request(WRITE)) == "06 00 00 00 07"


async def test_units_and_broadcast_are_filtered(tmp_path: Path) -> None:
    rules = tmp_path / "rules.toml"
    rules.write_text(
        'default_role = "any"\n[roles.any]\nfunction_codes = [3, 6]\n'
        f"units = [{UNIT}]\nbroadcast = false\n"
    )
    async with line(listen=(Listen("tcp://127.0.0.1:0", rules=str(rules)),)) as served:
        seen = served.messages
        async with client(served.gateway) as tcp:
            assert (await tcp.request(READ, unit=UNIT + 1)) == "83 01"
            await tcp.send(WRITE, unit=0)
            assert (await tcp.receive()).pdu.hex(" ") == "86 01"  # type: ignore[union-attr]
            assert (await tcp.request("0100000001")) == "81 01"
            assert (await tcp.request(READ)).startswith("03 04")
        assert served.messages == seen + 1
        assert served.gateway.counters.refused_by_rules == 3


async def test_a_rule_file_is_checked_before_anything_opens(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[roles.x]\nfunction_codes = [3]\nbroadcast = 2\n")
    with pytest.raises(ConfigError, match=r"roles\.x\.broadcast: must be true or false"):
        async with gateway("/dev/null-not-opened", [Listen("tcp://127.0.0.1:0", rules=bad)]):
            pass
    with pytest.raises(InvalidValue, match="a tls:// listener needs rules"):
        async with gateway("/dev/null-not-opened", ["tls://127.0.0.1:0"]):
            pass


async def test_a_tls_listener_grants_each_role_its_rule(tmp_path: Path) -> None:
    from tests.transport.certificates import Authority

    ca = Authority(tmp_path)
    server = ca.issue("server", server=True)
    viewer = ca.issue("viewer", role="viewer")
    operator = ca.issue("operator", role="operator")
    rules = RoleRules({"viewer": VIEWER.roles["viewer"], "operator": AccessRule(frozenset({3, 6}))})
    tls = server_tls_context(server.certfile, server.keyfile, ca.cafile)
    async with line(listen=(Listen("tls://127.0.0.1:0", rules=rules),), tls=tls) as served:
        for who, expected in ((viewer, "86 01"), (operator, "06 00 00 00 07")):
            context = client_tls_context(who.certfile, who.keyfile, ca.cafile)
            stream = await anyio.connect_tcp(
                "127.0.0.1",
                served.gateway.port,
                ssl_context=context,
                tls_hostname="localhost",
                tls_standard_compatible=False,
            )
            async with stream:
                tcp = TcpClient(stream)  # type: ignore[arg-type]
                assert (await tcp.request(WRITE)) == expected
                assert (await tcp.request(READ)).startswith("03 04")
        assert served.gateway.counters.refused_by_rules == 1
