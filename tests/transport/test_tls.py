"""Modbus/TCP Security: mutual TLS, the role in the certificate, and authorization by role."""

from __future__ import annotations

import contextlib
import logging
import re
import ssl
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import pytest
from anyio.streams.tls import TLSStream
from hypothesis import given
from hypothesis import strategies as st

import aiortu
from aiortu.core.mbap import decode_adu, encode_adu
from aiortu.errors import ConfigError, InvalidValue, PortError
from aiortu.slave import ModbusTlsServer
from aiortu.transport import (
    WRITE_FUNCTION_CODES,
    AccessRule,
    CertificateError,
    RoleRules,
    certificate_role,
    load_rules,
)
from aiortu.transport._tls import server_refusal
from tests.transport.certificates import Authority, Issued, der_utf8

pytestmark = pytest.mark.timeout(60)

RULES = RoleRules(
    {
        "operator": AccessRule(frozenset({1, 2, 3, 4, 5, 6, 8, 15, 16, 21, 22, 23})),
        "viewer": AccessRule(
            frozenset({1, 2, 3, 4, 5, 6, 8, 15, 16, 21, 22, 23, 43}), read_only=True
        ),
        "unit1": AccessRule(frozenset({3}), units=frozenset({1}), addresses=((0, 4),)),
    }
)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    directory = tmp_path_factory.mktemp("pki")
    ca = Authority(directory)
    stranger_ca = Authority(directory, "another CA")
    return {
        "ca": ca,
        "server": ca.issue("server", server=True),
        "operator": ca.issue("operator", role="operator"),
        "viewer": ca.issue("viewer", role="viewer"),
        "unit1": ca.issue("unit1", role="unit1"),
        "nobody": ca.issue("nobody"),
        "expired": ca.issue("expired", role="operator", expired=True),
        "untrusted": stranger_ca.issue("untrusted", role="operator"),
        "untrusted_server": stranger_ca.issue("untrusted-server", server=True),
    }


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(
        holding_registers={0: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]},
        coils={0: [0] * 16},
        files={4: [0] * 8},
    )


@asynccontextmanager
async def tls_server(pki: dict[str, Any], **options: Any) -> AsyncIterator[ModbusTlsServer]:
    server: Issued = pki["server"]
    options.setdefault("rules", RULES)
    async with aiortu.serve(
        "tls://127.0.0.1:0",
        {1: _store(), 2: _store()},
        certfile=server.certfile,
        keyfile=server.keyfile,
        cafile=pki["ca"].cafile,
        **options,
    ) as running:
        assert isinstance(running, ModbusTlsServer)
        yield running


def _client_options(pki: dict[str, Any], who: str) -> dict[str, Any]:
    issued: Issued = pki[who]
    return {"certfile": issued.certfile, "keyfile": issued.keyfile, "cafile": pki["ca"].cafile}


@asynccontextmanager
async def tls_master(
    pki: dict[str, Any], server: ModbusTlsServer, who: str
) -> AsyncIterator[aiortu.Master]:
    async with aiortu.open_master(
        f"tls://127.0.0.1:{server.port}", timeout=2.0, retries=0, **_client_options(pki, who)
    ) as master:
        yield master


# -- the role in the certificate --------------------------------------------------------


def test_the_role_is_read_from_the_certificate(pki: dict[str, Any]) -> None:
    assert certificate_role(pki["operator"].der) == "operator"
    assert certificate_role(pki["nobody"].der) is None
    assert certificate_role(pki["server"].der) is None


@given(st.text(max_size=300))
def test_any_role_text_round_trips(pki: dict[str, Any], role: str) -> None:
    issued = pki["ca"].issue("someone", role=role)
    assert certificate_role(issued.der) == role


def test_a_role_that_is_no_utf8string_is_refused(pki: dict[str, Any]) -> None:
    issued = pki["ca"].issue("printable", role_value=b"\x13\x08operator")  # PrintableString
    with pytest.raises(CertificateError, match=r"holds no UTF8String"):
        certificate_role(issued.der)


@given(st.binary(max_size=400))
def test_random_der_is_read_or_refused_cleanly(data: bytes) -> None:
    try:
        certificate_role(data)
    except CertificateError as error:
        message = str(error)
        assert "\n" not in message


@pytest.mark.parametrize("cut", [1, 10, 100, 200])
def test_a_truncated_certificate_is_refused(pki: dict[str, Any], cut: int) -> None:
    der = pki["operator"].der
    with pytest.raises(CertificateError):
        certificate_role(der[: len(der) - cut])


# -- mutual TLS -------------------------------------------------------------------------


async def test_an_operator_reads_and_writes(pki: dict[str, Any]) -> None:
    async with tls_server(pki) as server, tls_master(pki, server, "operator") as master:
        await master.write_registers(1, 0, [11, 12])
        assert await master.read_holding_registers(1, 0, 3) == [11, 12, 3]
        await master.write_coil(2, 3, True)
        assert server.denied == 0


async def test_a_read_only_role_is_refused_on_every_write_code(
    pki: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    writes = {
        0x05: "05 0001 FF00",
        0x06: "06 0001 0007",
        0x08: "08 0001 0000",
        0x0F: "0F 0000 0003 01 05",
        0x10: "10 0000 0001 02 0007",
        0x15: "15 09 06 0004 0001 0001 0007",
        0x16: "16 0000 00F2 0025",
        0x17: "17 0000 0001 0001 0001 02 0007",
    }
    assert set(writes) == WRITE_FUNCTION_CODES
    async with tls_server(pki) as server, tls_master(pki, server, "viewer") as master:
        assert await master.read_holding_registers(1, 0, 2) == [1, 2]
        for code, pdu in writes.items():
            reply = await master.execute(1, aiortu.RawPDU.decode(bytes.fromhex(pdu)))
            assert reply.encode() == bytes((code | 0x80, 0x01)), hex(code)
        assert server.denied == len(writes)
        assert await master.read_holding_registers(1, 0, 2) == [1, 2]  # nothing was written
    warnings = [r.getMessage() for r in caplog.records if "refused a request" in r.getMessage()]
    assert len(warnings) == 1, "the first refusal of a connection is a warning, the rest debug"
    assert "refused a request of 127.0.0.1:" in warnings[0]
    assert (
        "(role 'viewer') to unit 1: function code 0x05 writes and the role is read-only"
        in (warnings[0])
    )


async def test_units_and_address_ranges_bound_a_role(pki: dict[str, Any]) -> None:
    async with tls_server(pki) as server, tls_master(pki, server, "unit1") as master:
        assert await master.read_holding_registers(1, 0, 5) == [1, 2, 3, 4, 5]
        for unit, address, count in [(2, 0, 1), (1, 0, 6), (1, 5, 1)]:
            with pytest.raises(aiortu.ExceptionResponse) as caught:
                await master.read_holding_registers(unit, address, count)
            assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_FUNCTION
        with pytest.raises(aiortu.ExceptionResponse):
            await master.read_coils(1, 0, 1)
        assert server.denied == 4


async def test_a_certificate_without_a_role_gets_the_default_or_nothing(
    pki: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    async with tls_server(pki) as server, tls_master(pki, server, "nobody") as master:
        with pytest.raises(aiortu.ExceptionResponse) as caught:
            await master.read_holding_registers(1, 0, 1)
        assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_FUNCTION
    assert any(
        "carries no role (extension 1.3.6.1.4.1.50316.802.1) and there is no default role"
        in r.getMessage()
        for r in caplog.records
    )
    viewer_default = RoleRules(RULES.roles, default_role="viewer")
    async with (
        tls_server(pki, rules=viewer_default) as server,
        tls_master(pki, server, "nobody") as master,
    ):
        assert await master.read_holding_registers(1, 0, 1) == [1]
        with pytest.raises(aiortu.ExceptionResponse):
            await master.write_register(1, 0, 5)


async def _raw_tls_exchange(
    port: int, context: ssl.SSLContext, hostname: str = "127.0.0.1"
) -> bytes | None:
    """One read request over a hand-made TLS connection; the reply, or None when the server
    closes the connection or says nothing within 2 s."""
    stream = await anyio.connect_tcp("127.0.0.1", port)
    try:
        with anyio.move_on_after(2):
            tls = await TLSStream.wrap(stream, hostname=hostname, ssl_context=context)
            await tls.send(encode_adu(1, 1, bytes.fromhex("03 0000 0001")))
            return await tls.receive()
    except (anyio.BrokenResourceError, anyio.EndOfStream, ssl.SSLError, OSError):
        return None
    finally:
        await anyio.aclose_forcefully(stream)
    return None


def _context(pki: dict[str, Any], who: str | None) -> ssl.SSLContext:
    context = ssl.create_default_context(cafile=str(pki["ca"].cafile))
    if who is not None:
        context.load_cert_chain(pki[who].certfile, pki[who].keyfile)
    return context


@pytest.mark.parametrize(
    ("who", "words"),
    [
        ("expired", "its certificate was refused (certificate has expired)"),
        ("untrusted", "its certificate was refused (unable to get local issuer certificate)"),
        (None, "it sent no client certificate"),
    ],
)
async def test_a_bad_client_certificate_is_refused_in_one_sentence(
    pki: dict[str, Any], caplog: pytest.LogCaptureFixture, who: str | None, words: str
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    async with tls_server(pki) as server:
        assert await _raw_tls_exchange(server.port, _context(pki, who)) is None
        assert server.handshake_failures == 1, "refused in the handshake"
        assert await _raw_tls_exchange(server.port, _context(pki, "operator")) is not None
    (line,) = [r for r in caplog.records if "closed the connection of" in r.getMessage()]
    assert line.getMessage().startswith("Modbus/TCP Security: closed the connection of 127.0.0.1:")
    assert line.getMessage().endswith(words), line.getMessage()
    assert line.exc_info is None


async def test_a_plaintext_client_on_a_tls_port_is_refused_in_one_sentence(
    pki: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    async with tls_server(pki) as server:
        stream = await anyio.connect_tcp("127.0.0.1", server.port)
        async with stream:
            await stream.send(encode_adu(1, 1, bytes.fromhex("03 0000 0001")))
            with anyio.fail_after(5):
                reply = b""
                try:
                    reply = await stream.receive()
                    while True:  # a TLS alert at most, then the end
                        reply += await stream.receive()
                except (anyio.EndOfStream, anyio.BrokenResourceError):
                    pass
        with pytest.raises(Exception):  # noqa: B017, PT011 - whatever came back is no ADU
            decode_adu(reply)
        for _ in range(3):  # more of them: counted, logged at debug level
            stream = await anyio.connect_tcp("127.0.0.1", server.port)
            async with stream:
                await stream.send(b"GET / HTTP/1.0\r\n\r\n")
                with (
                    anyio.fail_after(5),
                    contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError),
                ):
                    while True:
                        await stream.receive()
        assert server.handshake_failures == 4
    lines = [r for r in caplog.records if "closed the connection of" in r.getMessage()]
    assert len(lines) == 1, "one warning, then counts"
    assert lines[0].getMessage().endswith("it does not speak TLS (a plaintext Modbus TCP client?)")
    assert all(r.exc_info is None for r in caplog.records), "no traceback in the log"


async def test_the_master_refuses_an_untrusted_server(pki: dict[str, Any]) -> None:
    untrusted: Issued = pki["untrusted_server"]
    async with aiortu.serve(
        "tls://127.0.0.1:0",
        {1: _store()},
        certfile=untrusted.certfile,
        keyfile=untrusted.keyfile,
        cafile=pki["ca"].cafile,
        rules=RULES,
    ) as server:
        with pytest.raises(PortError) as caught:
            async with aiortu.open_master(
                f"tls://127.0.0.1:{server.port}", **_client_options(pki, "operator")
            ):
                pass
    assert str(caught.value) == (
        f"tls://127.0.0.1:{server.port}: the server's certificate was refused "
        "(unable to get local issuer certificate)"
    )


async def test_settings_errors_are_one_sentence(pki: dict[str, Any], tmp_path: Path) -> None:
    server: Issued = pki["server"]
    with pytest.raises(InvalidValue, match=r"^keyfile is missing: Modbus/TCP Security needs "
                       r"the server's certificate and private key$"):  # fmt: skip
        async with aiortu.serve(
            "tls://127.0.0.1:0", {1: _store()}, certfile=server.certfile,
            cafile=pki["ca"].cafile, rules=RULES,
        ):  # fmt: skip
            pass
    with pytest.raises(InvalidValue, match=r"^certfile is missing: .* the client's certificate"):
        await aiortu.transport.open_stream("tls://127.0.0.1:802", cafile=pki["ca"].cafile)
    with pytest.raises(InvalidValue, match=r"^cannot load the TLS cafile: No such file"):
        await aiortu.transport.open_stream(
            "tls://127.0.0.1:802",
            certfile=server.certfile,
            keyfile=server.keyfile,
            cafile=tmp_path / "missing.pem",
        )


# -- the rule file ----------------------------------------------------------------------


def test_a_rule_file_loads(tmp_path: Path) -> None:
    path = tmp_path / "rules.toml"
    path.write_text(
        'default_role = "viewer"\n'
        "[roles.viewer]\nfunction_codes = [1, 2, 3, 4]\nread_only = true\n"
        "[roles.operator]\nfunction_codes = [3, 16]\nunits = [1, 17]\n"
        "addresses = [[0, 99], [200, 299]]\n",
        encoding="utf-8",
    )
    rules = load_rules(path)
    assert rules.default_role == "viewer"
    assert rules.roles["operator"] == AccessRule(
        frozenset({3, 16}), frozenset({1, 17}), ((0, 99), (200, 299))
    )
    assert rules.refusal(None, 1, bytes.fromhex("03 0000 0001")) is None
    assert rules.refusal("operator", 17, bytes.fromhex("03 00C8 0064")) is None
    assert rules.refusal("operator", 17, bytes.fromhex("03 0063 0002")) == (
        "addresses 99..100 are outside the allowed ranges"
    )
    assert rules.refusal("ghost", 1, b"\x03") == "no rule grants the role 'ghost' anything"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[roles.viewer]\nfunction_codes = [3]\nreadonly = true\n",
         "roles.viewer.readonly: unknown key (expected addresses, broadcast, function_codes, "
         "read_only, units)"),
        ("[roles.viewer]\nfunction_codes = [3]\nbroadcast = 1\n",
         "roles.viewer.broadcast: must be true or false"),
        ("defaults = 1\n", "defaults: unknown key (expected default_role, roles)"),
        ("[roles.viewer]\nunits = [1]\n", "roles.viewer.function_codes: is required"),
        ("[roles.viewer]\nfunction_codes = [300]\n", "300 is not a number in 1..127"),
        ("[roles.viewer]\nfunction_codes = [3]\naddresses = [[5, 1]]\n",
         "[5, 1] is not a [first, last] pair in 0..65535"),
        ("[roles.viewer\n", "(file): not valid TOML"),
    ],
)  # fmt: skip
def test_a_bad_rule_file_is_one_line_naming_the_key(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "rules.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        load_rules(path)
    assert str(caught.value).startswith(f"{path}: ")
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_the_security_pages_rule_file_loads_and_its_error_is_the_loaders(
    tmp_path: Path,
) -> None:
    page = (Path(__file__).parents[2] / "docs" / "security.md").read_text(encoding="utf-8")
    example = re.search(r"```toml\n(# rules\.toml\n.*?)```", page, re.DOTALL)
    assert example is not None
    path = tmp_path / "rules.toml"
    path.write_text(example.group(1), encoding="utf-8")
    rules = load_rules(path)
    assert rules.default_role == "viewer"
    assert rules.roles["viewer"].read_only
    # The page's table of keys names every key the loader takes.
    path.write_text("[roles.viewer]\nfunction_codes = [3]\nreadonly = true\n", encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        load_rules(path)
    message = str(caught.value).replace(str(path), "rules.toml")
    assert f"`{message}`" in page
    expected = re.search(r"\(expected ([a-z_, ]+)\)", message)
    assert expected is not None
    for key in expected.group(1).split(", "):
        assert f"| `roles.NAME.{key}` |" in page, key


def test_der_utf8_long_form() -> None:
    assert der_utf8("a" * 200)[:3] == b"\x0c\x81\xc8"


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_modbus_tls_runs_on_both_backends(pki: dict[str, Any], backend: str) -> None:
    async def scenario() -> None:
        with anyio.fail_after(10):
            async with tls_server(pki) as server, tls_master(pki, server, "viewer") as master:
                assert await master.read_holding_registers(1, 0, 2) == [1, 2]
                with pytest.raises(aiortu.ExceptionResponse):
                    await master.write_register(1, 0, 5)

    anyio.run(scenario, backend=backend)


# -- a client certificate the server refuses after the handshake --------------------------


@contextlib.contextmanager
def _alerting_server(pki: dict[str, Any], replies: int = 0) -> Any:
    """A bare TLS 1.3 server on a thread for one connection: it refuses a bad client
    certificate with the alert saying why (the blocking ssl module sends it), or answers
    `replies` reads with [7] and closes; yields its port."""
    import socket
    import threading

    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH, cafile=str(pki["ca"].cafile))
    context.load_cert_chain(pki["server"].certfile, pki["server"].keyfile)
    context.verify_mode = ssl.CERT_REQUIRED
    listener = socket.create_server(("127.0.0.1", 0))
    listener.settimeout(10)

    def serve() -> None:
        with contextlib.suppress(OSError), listener.accept()[0] as raw:
            raw.settimeout(10)
            tls = context.wrap_socket(raw, server_side=True, do_handshake_on_connect=False)
            with tls:
                with contextlib.suppress(ssl.SSLError):
                    tls.do_handshake()
                    for _ in range(replies):
                        transaction = decode_adu(tls.recv(260)).transaction_id
                        tls.sendall(encode_adu(transaction, 1, bytes.fromhex("03 02 0007")))
                # Read the client's request before closing: no reset overtakes the alert.
                tls.shutdown(socket.SHUT_WR)
                while tls.recv(4096):
                    pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield listener.getsockname()[1]
    finally:
        listener.close()
        thread.join(10)


async def _first_request(pki: dict[str, Any], port: int, who: str) -> BaseException:
    with anyio.fail_after(10):
        try:
            async with aiortu.open_master(
                f"tls://127.0.0.1:{port}", timeout=2.0, retries=0, **_client_options(pki, who)
            ) as master:
                await master.read_holding_registers(1, 0, 1)
        except Exception as error:  # the test looks at what came out
            return error
    raise AssertionError("the request succeeded")


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@pytest.mark.parametrize(
    ("who", "words"),
    [
        ("expired", "the server refused this client's certificate: it has expired"),
        ("untrusted", "the server refused this client's certificate: it was signed by a CA "
                      "the server does not trust"),
    ],
)  # fmt: skip
def test_a_refused_client_certificate_is_one_sentence_with_the_alerts_reason(
    pki: dict[str, Any], backend: str, who: str, words: str
) -> None:
    async def scenario() -> BaseException:
        with _alerting_server(pki) as port:
            return await _first_request(pki, port, who)

    error = anyio.run(scenario, backend=backend)
    assert type(error) is aiortu.ConnectionLost, repr(error)
    assert str(error).startswith("the line failed: the port is gone (tls://127.0.0.1:")
    assert str(error).endswith(f": {words})"), str(error)


_REFUSED = "the server refused this client's certificate: "
_OWN_SERVER_WORDS = {
    "expired": _REFUSED + "it has expired",
    "untrusted": _REFUSED + "it was signed by a CA the server does not trust",
}


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@pytest.mark.parametrize("who", ["expired", "untrusted"])
def test_aiortus_own_server_tells_the_master_why_it_refused_the_certificate(
    pki: dict[str, Any], backend: str, who: str
) -> None:
    """The server's TLS layer writes the alert before it closes, and the master names the
    reason: on asyncio the pushed connection's own layer, on trio anyio's TLS stream."""

    async def scenario() -> BaseException:
        async with tls_server(pki) as server:
            return await _first_request(pki, server.port, who)

    error = anyio.run(scenario, backend=backend)
    assert type(error) is aiortu.ConnectionLost, repr(error)
    assert str(error).endswith(f": {_OWN_SERVER_WORDS[who]})"), str(error)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_aiortus_own_server_tells_a_client_without_a_certificate_why(
    pki: dict[str, Any], backend: str
) -> None:
    """A client with no certificate at all (aiortu's master always has one) gets the alert
    that names what is missing, in the sentence a master would give."""

    async def scenario() -> ssl.SSLError:
        async with tls_server(pki) as server:
            stream = await anyio.connect_tcp("127.0.0.1", server.port)
            async with stream:
                with anyio.fail_after(5):
                    tls = await TLSStream.wrap(
                        stream, hostname="127.0.0.1", ssl_context=_context(pki, None)
                    )
                    await tls.send(encode_adu(1, 1, bytes.fromhex("03 0000 0001")))
                    with pytest.raises(ssl.SSLError) as caught:
                        await tls.receive()
        return caught.value

    refused = server_refusal("tls://server", anyio.run(scenario, backend=backend))
    assert str(refused) == "tls://server: " + _REFUSED + "the server requires one"


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_master_without_a_client_certificate_is_told_before_connecting(
    pki: dict[str, Any], backend: str
) -> None:
    async def scenario() -> None:
        with pytest.raises(InvalidValue) as caught:
            async with aiortu.open_master("tls://127.0.0.1:1", cafile=pki["ca"].cafile):
                pass
        assert str(caught.value) == (
            "certfile is missing: Modbus/TCP Security needs the client's certificate and"
            " private key"
        )

    anyio.run(scenario, backend=backend)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_an_error_in_a_masters_body_comes_out_unwrapped(pki: dict[str, Any], backend: str) -> None:
    async def scenario() -> None:
        async with tls_server(pki) as server:
            with pytest.raises(aiortu.ExceptionResponse):
                async with tls_master(pki, server, "viewer") as master:
                    await master.write_register(1, 0, 5)

    anyio.run(scenario, backend=backend)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_server_that_goes_away_after_replying_is_no_refusal(
    pki: dict[str, Any], backend: str
) -> None:
    async def scenario() -> str:
        with anyio.fail_after(10), _alerting_server(pki, replies=1) as port:
            async with aiortu.open_master(
                f"tls://127.0.0.1:{port}", timeout=2.0, retries=0,
                **_client_options(pki, "operator"),
            ) as master:  # fmt: skip
                assert await master.read_holding_registers(1, 0, 1) == [7]
                with pytest.raises(aiortu.ConnectionLost) as caught:
                    await master.read_holding_registers(1, 0, 1)
                return str(caught.value)

    message = anyio.run(scenario, backend=backend)
    assert "certificate" not in message, message


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_stream_closed_by_the_master_is_no_refusal(pki: dict[str, Any], backend: str) -> None:
    async def scenario() -> None:
        with anyio.fail_after(10):
            async with tls_server(pki) as server:
                stream = await aiortu.transport.open_stream(
                    f"tls://127.0.0.1:{server.port}", **_client_options(pki, "operator")
                )
                await stream.aclose()
                with pytest.raises(anyio.ClosedResourceError):
                    await stream.receive()

    anyio.run(scenario, backend=backend)
