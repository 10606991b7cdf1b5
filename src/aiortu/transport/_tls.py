"""Modbus/TCP Security: MBAP inside mutual TLS, and the client's role from its certificate.

The Modbus.org spec (MB-TCP-Security) puts the Modbus TCP ADU inside TLS 1.2 or later, on port
802, with both ends authenticated by X.509v3 certificates. The client's role travels in its
certificate, in the extension [`ROLE_OID`][aiortu.transport.ROLE_OID] holding an ASN.1
UTF8String; the server grants rights by role (see
[`RoleRules`][aiortu.transport.RoleRules]).

- [`open_modbus_tls`][aiortu.transport.open_modbus_tls] connects a master: a client certificate
  and key are required, the server's certificate is checked against `cafile` (and its name
  against the host), and the connection is a
  [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] like plain Modbus TCP.
- [`server_tls_context`][aiortu.transport.server_tls_context] and
  [`TlsListener`][aiortu.transport.TlsListener] make a server's side: a client certificate
  signed by `cafile` is required; a client that fails the handshake (plain TCP, no certificate,
  an expired or untrusted one) is sent TLS's alert saying why, logged in one sentence and
  closed.
- [`certificate_role`][aiortu.transport.certificate_role] reads the role out of a DER
  certificate with a small DER reader of its own, so no third-party package is needed.

Every setting error is one sentence naming what is missing or wrong: a certificate or key that
cannot be read, a TLS port given without a key.
A server that refuses the master's certificate after a TLS 1.3 handshake is told at the first
request, in one sentence with the alert's reason (see `server_refusal`), not as a bare reset.
"""

from __future__ import annotations

import contextlib
import logging
import ssl
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any, Final

import anyio
import anyio.abc
from anyio.streams.tls import TLSListener, TLSStream

from aiortu._log import get_logger
from aiortu.errors import InvalidValue, PortError
from aiortu.transport import _tcp_push  # its predicate, looked up at each call
from aiortu.transport._listen import after_handshake, peer_address
from aiortu.transport._mbap_stream import ModbusTcpCounters, ModbusTcpStream
from aiortu.transport._tcp import connect_protocol, open_tcp_connection
from aiortu.transport._tcp_push import PushConnectionStream
from aiortu.transport._tls_bio import TlsBioTransport
from aiortu.transport._url import TLS_SCHEME, format_tcp_url

__all__ = (
    "ROLE_OID",
    "CertificateError",
    "TlsListener",
    "certificate_role",
    "client_tls_context",
    "open_modbus_tls",
    "server_tls_context",
)

_log = get_logger(__name__)

ROLE_OID: Final = "1.3.6.1.4.1.50316.802.1"
"""The certificate extension that carries a Modbus/TCP Security client's role."""

PathLike = str | Path


class CertificateError(ValueError):
    """A certificate whose DER cannot be read, or whose role extension holds no UTF8String."""


# -- the role, read from DER -------------------------------------------------------------


def _encode_oid(dotted: str) -> bytes:
    first, second, *rest = (int(part) for part in dotted.split("."))
    out = bytearray((first * 40 + second,))
    for number in rest:
        chunk = [number & 0x7F]
        higher = number >> 7
        while higher:
            chunk.append(0x80 | (higher & 0x7F))
            higher >>= 7
        out += bytes(reversed(chunk))
    return bytes(out)


_ROLE_OID_DER: Final = _encode_oid(ROLE_OID)
_SEQUENCE, _OID, _OCTET_STRING, _UTF8_STRING, _EXTENSIONS = 0x30, 0x06, 0x04, 0x0C, 0xA3


def _element(data: bytes, position: int, end: int) -> tuple[int, int, int]:
    """The tag, content start and content end of the DER element at `position`."""
    if position + 2 > end:
        raise CertificateError("the certificate's DER ends inside an element header")
    tag, length = data[position], data[position + 1]
    start = position + 2
    if length & 0x80:
        size = length & 0x7F
        if not 1 <= size <= 4 or start + size > end:
            raise CertificateError("the certificate's DER has a length it cannot hold")
        length = int.from_bytes(data[start : start + size], "big")
        start += size
    if start + length > end:
        raise CertificateError("the certificate's DER ends inside an element")
    return tag, start, start + length


def _children(data: bytes, start: int, end: int) -> list[tuple[int, int, int]]:
    children = []
    while start < end:
        child = _element(data, start, end)
        children.append(child)
        start = child[2]
    return children


def certificate_role(der: bytes) -> str | None:
    """The role in the DER certificate `der` (extension [`ROLE_OID`][aiortu.transport.ROLE_OID]),
    or None when it has no such extension.

    Raises [`CertificateError`][aiortu.transport.CertificateError] for DER it cannot read or a role
    extension that holds no UTF8String in UTF-8.
    """
    tag, start, end = _element(der, 0, len(der))
    if tag != _SEQUENCE:
        raise CertificateError("a certificate is a DER SEQUENCE")
    tbs_tag, tbs_start, tbs_end = _element(der, start, end)
    if tbs_tag != _SEQUENCE:
        raise CertificateError("a certificate begins with its to-be-signed SEQUENCE")
    for tag, field_start, field_end in _children(der, tbs_start, tbs_end):
        if tag != _EXTENSIONS:
            continue
        (list_tag, list_start, list_end), *_ = _children(der, field_start, field_end) or [(0, 0, 0)]
        if list_tag != _SEQUENCE:
            raise CertificateError("a certificate's extensions are a SEQUENCE")
        for _, ext_start, ext_end in _children(der, list_start, list_end):
            parts = _children(der, ext_start, ext_end)
            if len(parts) < 2 or parts[0][0] != _OID:
                raise CertificateError("an extension begins with its OID")
            if der[parts[0][1] : parts[0][2]] != _ROLE_OID_DER:
                continue
            value_tag, value_start, value_end = parts[-1]
            if value_tag != _OCTET_STRING:
                raise CertificateError("the role extension's value is not an OCTET STRING")
            inner_tag, inner_start, inner_end = _element(der, value_start, value_end)
            if inner_tag != _UTF8_STRING or inner_end != value_end:
                raise CertificateError(f"the role extension ({ROLE_OID}) holds no UTF8String")
            try:
                return der[inner_start:inner_end].decode("utf-8")
            except UnicodeDecodeError:
                raise CertificateError("the role extension's UTF8String is not UTF-8") from None
    return None


# -- contexts ----------------------------------------------------------------------------


def _context(
    purpose: ssl.Purpose,
    certfile: PathLike | None,
    keyfile: PathLike | None,
    cafile: PathLike | None,
) -> ssl.SSLContext:
    side = "server" if purpose is ssl.Purpose.CLIENT_AUTH else "client"
    if cafile is None:
        peers = "clients" if purpose is ssl.Purpose.CLIENT_AUTH else "servers"
        raise InvalidValue(
            "cafile", None, "given", f"Modbus/TCP Security trusts the {peers} its CAs signed",
            message="cafile is missing",
        )  # fmt: skip
    if certfile is None or keyfile is None:
        missing = "certfile" if certfile is None else "keyfile"
        raise InvalidValue(
            missing,
            None,
            "given",
            f"Modbus/TCP Security needs the {side}'s certificate and private key",
            message=f"{missing} is missing",
        )
    context = ssl.create_default_context(purpose)
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    context.options |= ssl.OP_NO_RENEGOTIATION  # a session's keys and peers stay as agreed
    context.verify_mode = ssl.CERT_REQUIRED
    try:
        context.load_cert_chain(certfile, keyfile)
    except (OSError, ssl.SSLError) as error:
        raise _unreadable("certfile and keyfile", certfile, error) from None
    try:
        context.load_verify_locations(cafile)
    except (OSError, ssl.SSLError) as error:
        raise _unreadable("cafile", cafile, error) from None
    return context


def _unreadable(name: str, path: PathLike, error: OSError) -> InvalidValue:
    reason = getattr(error, "strerror", None) or getattr(error, "reason", None) or str(error)
    return InvalidValue(
        name, str(path), "readable PEM", str(reason), message=f"cannot load the TLS {name}"
    )


def server_tls_context(
    certfile: PathLike | None, keyfile: PathLike | None, cafile: PathLike | None
) -> ssl.SSLContext:
    """A server's TLS context: TLS 1.2 or later, its certificate and key, and a client
    certificate signed by one of the CAs in `cafile` required.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] when a file is missing or unreadable.
    """
    return _context(ssl.Purpose.CLIENT_AUTH, certfile, keyfile, cafile)


def client_tls_context(
    certfile: PathLike | None, keyfile: PathLike | None, cafile: PathLike | None
) -> ssl.SSLContext:
    """A client's TLS context: TLS 1.2 or later, its certificate and key, and the server's
    certificate checked against the CAs in `cafile` and its name against the host."""
    return _context(ssl.Purpose.SERVER_AUTH, certfile, keyfile, cafile)


def describe_tls_failure(error: BaseException) -> str:
    """Why a TLS handshake failed, in words: not TLS at all, no certificate, an expired or
    untrusted one, or what the TLS library said."""
    if isinstance(error, ssl.SSLCertVerificationError):
        return f"its certificate was refused ({error.verify_message})"
    reason = getattr(error, "reason", None) or ""
    words = {
        "WRONG_VERSION_NUMBER": "it does not speak TLS (a plaintext Modbus TCP client?)",
        "HTTP_REQUEST": "it does not speak TLS",
        "PEER_DID_NOT_RETURN_A_CERTIFICATE": "it sent no client certificate",
        "UNSUPPORTED_PROTOCOL": "it offers only TLS older than 1.2",
        "TLSV1_ALERT_PROTOCOL_VERSION": "it offers only TLS older than 1.2",
        "TLSV1_ALERT_UNKNOWN_CA": "it does not trust our certificate (unknown CA)",
        "SSLV3_ALERT_CERTIFICATE_EXPIRED": "it refused our certificate as expired",
        "SSLV3_ALERT_BAD_CERTIFICATE": "it refused our certificate",
        "TLSV13_ALERT_CERTIFICATE_REQUIRED": "it requires a client certificate",
    }
    if reason in words:
        return words[reason]
    if isinstance(error, TimeoutError):
        return "the TLS handshake did not finish in time"
    if isinstance(error, anyio.EndOfStream | anyio.BrokenResourceError | ConnectionError):
        return "it closed the connection during the TLS handshake"
    return f"the TLS handshake failed ({reason or error})"


_REFUSALS: Final = {
    "SSLV3_ALERT_CERTIFICATE_EXPIRED": "it has expired",
    "TLSV1_ALERT_UNKNOWN_CA": "it was signed by a CA the server does not trust",
    "TLSV13_ALERT_CERTIFICATE_REQUIRED": "the server requires one",
    "SSLV3_ALERT_CERTIFICATE_REVOKED": "it was revoked",
    "SSLV3_ALERT_BAD_CERTIFICATE": "the server found it bad",
    "SSLV3_ALERT_UNSUPPORTED_CERTIFICATE": "the server does not support its kind",
    "SSLV3_ALERT_CERTIFICATE_UNKNOWN": "the server could not accept it",
    "TLSV1_ALERT_ACCESS_DENIED": "the server denies it access",
}


def server_refusal(where: str, error: BaseException) -> anyio.BrokenResourceError:
    """What a TLS connection to `where` ending with `error` before the server's first byte
    means: under TLS 1.3 a server refuses the client's certificate only after the handshake,
    with an alert (whose reason is given when the TLS library passes it on) or by closing."""
    tls_error = error if isinstance(error, ssl.SSLError) else error.__cause__
    reason = getattr(tls_error, "reason", None)
    if reason in _REFUSALS:
        why = f"the server refused this client's certificate: {_REFUSALS[reason]}"
    elif isinstance(tls_error, ssl.SSLError) and reason:
        why = f"the server ended the TLS session ({reason})"
    else:
        why = (
            "the server closed the connection before its first reply;"
            " it may have refused this client's certificate"
        )
    refused = anyio.BrokenResourceError(f"{where}: {why}")
    refused.__cause__ = error
    return refused


class _ClientTlsStream(TLSStream):
    """anyio's TLS stream for a master: an end before the server's first byte is told as
    `server_refusal` says."""

    where = ""
    heard = False

    async def receive(self, max_bytes: int = 65536) -> bytes:
        if self.heard:
            return await super().receive(max_bytes)
        try:
            data = await super().receive(max_bytes)
        except (anyio.EndOfStream, anyio.BrokenResourceError, ssl.SSLError) as error:
            raise server_refusal(self.where, error) from error
        self.heard = True
        return data


class _ServerTlsStream(TLSStream):
    """anyio's TLS stream for a server, which sends the alert of a TLS error before the
    error goes on: anyio leaves it in the outgoing BIO, and a connection closed without it
    tells the client nothing of why its certificate was refused (asyncio's pushed
    connections send it in `_tls_bio.py`).

    It overrides anyio's `_call_sslobject_method`, private but the one method every
    handshake step, read and write goes through; were it renamed, the trio tests of the
    master's reason would fail, not pass silently."""

    async def _call_sslobject_method(  # type: ignore[override]
        self, func: Callable[..., Any], *args: Any
    ) -> Any:
        try:
            return await super()._call_sslobject_method(func, *args)
        except ssl.SSLError:
            outgoing = self._write_bio
            if outgoing.pending:  # the alert; the connection may be gone already
                with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError):
                    await self.transport_stream.send(outgoing.read())
            raise


class TlsListener(TLSListener):
    """anyio's TLS listener that sends a failed handshake's alert (so the client can say
    why), logs the failure in one sentence (who, and why), not with a traceback, and passes on
    the listening address of the listener it wraps.

    The first failed handshake is logged as a warning and the later ones at debug level, so
    that a flood of them costs counts, not log lines:
    [`handshake_failures`][aiortu.transport.TlsListener.handshake_failures] counts them all.
    """

    handshake_failures: int = 0
    """Handshakes that failed (plaintext, no certificate, an expired or untrusted one, ...)."""

    async def serve(  # type: ignore[override]
        self,
        handler: Callable[[anyio.abc.ByteStream], Any],
        task_group: anyio.abc.TaskGroup | None = None,
    ) -> None:
        """Serve each connection of the wrapped listener whose handshake succeeds with
        `handler` ([`serve_listener`][aiortu.transport.serve_listener] accepts with a limit and
        calls [`handshake`][aiortu.transport.TlsListener.handshake] itself)."""
        await self.listener.serve(after_handshake(self, handler), task_group)

    async def handshake(self, stream: anyio.abc.ByteStream) -> anyio.abc.ByteStream | None:
        """The TLS stream over the accepted `stream` once the handshake is done within
        `handshake_timeout`; None when it failed (logged, counted, `stream` closed)."""
        try:
            with anyio.fail_after(self.handshake_timeout):
                return await _ServerTlsStream.wrap(
                    stream,
                    ssl_context=self.ssl_context,
                    standard_compatible=self.standard_compatible,
                )
        except BaseException as error:
            await self.handle_handshake_error(error, stream)
            return None

    async def handle_handshake_error(  # type: ignore[override]
        self, exc: BaseException, stream: anyio.abc.AnyByteStream
    ) -> None:
        peer = peer_address(stream) if isinstance(stream, anyio.abc.ByteStream) else "a client"
        if isinstance(exc, anyio.get_cancelled_exc_class()) or not isinstance(exc, Exception):
            await anyio.aclose_forcefully(stream)
            raise exc
        # Counted before the close, which is what the client sees.
        self.handshake_failures += 1
        _log.log(
            logging.WARNING if self.handshake_failures == 1 else logging.DEBUG,
            "Modbus/TCP Security: closed the connection of %s: %s",
            peer,
            describe_tls_failure(exc),
        )
        await anyio.aclose_forcefully(stream)

    @property
    def extra_attributes(self) -> Mapping[Any, Callable[[], Any]]:
        return {**self.listener.extra_attributes, **super().extra_attributes}


async def open_modbus_tls(
    host: str,
    port: int,
    *,
    certfile: PathLike | None = None,
    keyfile: PathLike | None = None,
    cafile: PathLike | None = None,
    connect_timeout: float = 5.0,
    counters: ModbusTcpCounters | None = None,
) -> ModbusTcpStream | PushConnectionStream:
    """Connect to the Modbus/TCP Security server at `host`:`port` with the client certificate
    `certfile` and its key `keyfile`, trusting the CAs in `cafile`; return a stream of RTU
    frames, as [`open_modbus_tcp`][aiortu.transport.open_modbus_tcp] does (on asyncio a
    [`PushConnectionStream`][aiortu.transport.PushConnectionStream] with its own TLS layer on
    asyncio's plain transport, elsewhere a
    [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] over anyio's TLS stream).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a missing or unreadable file,
    [`PortNotFound`][aiortu.errors.PortNotFound] when the server cannot be reached, and
    [`PortError`][aiortu.errors.PortError] when the handshake fails (an untrusted or expired
    server certificate, or the server refusing ours), saying why in one sentence.
    """
    context = client_tls_context(certfile, keyfile, cafile)
    where = format_tcp_url(host, port, TLS_SCHEME)
    counters = counters if counters is not None else ModbusTcpCounters()
    if _tcp_push.push_connections():
        pushed = PushConnectionStream(counters, where)
        layer = TlsBioTransport(context, pushed.protocol, server_hostname=host)
        pushed.transport = layer
        await connect_protocol(
            host, port, layer, connect_timeout=connect_timeout, scheme=TLS_SCHEME
        )
        async with _handshake(where, connect_timeout, pushed):
            await layer.handshake()
        pushed.refusal = lambda error: server_refusal(where, error)
        return pushed
    stream = await open_tcp_connection(host, port, connect_timeout=connect_timeout, scheme="tls")
    async with _handshake(where, connect_timeout, stream):
        tls = await _ClientTlsStream.wrap(
            stream, hostname=host, ssl_context=context, standard_compatible=False
        )
    assert isinstance(tls, _ClientTlsStream)  # wrap() makes its own class
    tls.where = where
    return ModbusTcpStream(tls, counters)


@asynccontextmanager
async def _handshake(
    where: str, seconds: float, stream: anyio.abc.AsyncResource
) -> AsyncIterator[None]:
    """Bound the handshake by `seconds`; when it fails, close `stream` and raise
    [`PortError`][aiortu.errors.PortError] saying why in one sentence."""
    try:
        with anyio.fail_after(seconds):
            yield
    except Exception as error:
        await anyio.aclose_forcefully(stream)
        if isinstance(error, ssl.SSLCertVerificationError):
            message = f"the server's certificate was refused ({error.verify_message})"
        else:
            message = f"the TLS handshake failed: {describe_tls_failure(error)}"
        raise PortError(where, message) from None
