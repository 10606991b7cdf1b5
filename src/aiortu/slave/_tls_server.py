"""Modbus/TCP Security for the slave: the Modbus TCP server behind mutual TLS, with roles.

[`ModbusTlsServer`][aiortu.slave.ModbusTlsServer] is a
[`ModbusTcpServer`][aiortu.slave.ModbusTcpServer] whose connections are TLS 1.2 or later with a
client certificate signed by one of the CAs in `cafile`. Each connection's role is read from its
certificate once (extension [`ROLE_OID`][aiortu.transport.ROLE_OID]); every request is checked
against the [`RoleRules`][aiortu.transport.RoleRules] before it reaches a store: a refused one is
answered with exception 01 (illegal function), counted in
[`denied`][aiortu.slave.ModbusTlsServer.denied] and logged with the role, the peer and why (the
first refusal of a connection as a warning, the rest at debug level, so that a client cannot
flood the log). A client that fails the handshake (plain TCP, no certificate, an expired or
untrusted one) is closed and logged in one sentence (the first as a warning, the rest at debug
level; all counted in [`handshake_failures`][aiortu.slave.ModbusTlsServer.handshake_failures]).
`aiortu.serve("tls://0.0.0.0:802", {1: store}, certfile=..., keyfile=..., cafile=...,
rules="rules.toml")` runs one.
"""

from __future__ import annotations

import contextvars
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio
import anyio.abc
from anyio.streams.tls import TLSAttribute

from aiortu._log import get_logger
from aiortu.core.codes import ExceptionCode
from aiortu.core.mbap import Adu
from aiortu.core.pdu import encode_exception
from aiortu.errors import InvalidValue
from aiortu.slave._tcp_at_once import Permits
from aiortu.slave._tcp_server import ModbusTcpServer, _Outgoing
from aiortu.transport import (
    ROLE_OID,
    CertificateError,
    RoleRules,
    TlsListener,
    certificate_role,
    load_rules,
    peer_address,
    push_listener,
    pushed_listener,
    server_tls_context,
)

__all__ = ("ModbusTlsServer",)

_log = get_logger(__name__)

HANDSHAKE_TIMEOUT = 10.0
"""Seconds a client has to finish the TLS handshake."""


@dataclass(slots=True)
class _Client:
    """One connection's peer and role, and whether a refusal was logged as a warning yet."""

    peer: str
    role: str | None
    warned: bool = False


_CLIENT: contextvars.ContextVar[_Client] = contextvars.ContextVar("aiortu_tls_client")


class ModbusTlsServer(ModbusTcpServer):
    """A Modbus/TCP Security server for `units` (see the module docstring).

    `certfile` and `keyfile` are the server's certificate and private key (PEM), `cafile` the CAs
    whose client certificates are accepted, and `rules` a
    [`RoleRules`][aiortu.transport.RoleRules] or the path of a rule file
    ([`load_rules`][aiortu.transport.load_rules]); the other `options` are
    [`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]'s. Raises
    [`InvalidValue`][aiortu.errors.InvalidValue] for a missing or unreadable file and
    [`ConfigError`][aiortu.errors.ConfigError] for a bad rule file.
    """

    def __init__(
        self,
        units: Any,
        *,
        certfile: str | Path | None = None,
        keyfile: str | Path | None = None,
        cafile: str | Path | None = None,
        rules: RoleRules | str | Path | None = None,
        **options: Any,
    ) -> None:
        super().__init__(units, **options)
        self.tls_context = server_tls_context(certfile, keyfile, cafile)
        """The server's TLS context (TLS 1.2 or later, client certificates required)."""
        if rules is None:
            raise InvalidValue(
                "rules", None, "given", "a tls:// server grants each role what its rules allow",
                message="rules is missing",
            )  # fmt: skip
        self.rules = rules if isinstance(rules, RoleRules) else load_rules(rules)
        """The rights of each role."""
        self.denied = 0
        """Requests refused by the rules (answered with exception 01)."""
        self._listener: TlsListener | None = None

    @property
    def handshake_failures(self) -> int:
        """Connections closed because their TLS handshake failed (the first is logged as a
        warning, the rest at debug level)."""
        return 0 if self._listener is None else self._listener.handshake_failures

    async def serve(
        self,
        listener: anyio.abc.Listener[anyio.abc.ByteStream],
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Accept TLS connections on the TCP `listener` and serve each, until cancelled."""
        secure: TlsListener
        if push_listener(listener):
            secure = pushed_listener(
                listener, self.tls_context, standard_compatible=False,
                handshake_timeout=HANDSHAKE_TIMEOUT,
            )  # fmt: skip
        else:
            secure = TlsListener(
                listener, self.tls_context, standard_compatible=False,
                handshake_timeout=HANDSHAKE_TIMEOUT,
            )  # fmt: skip
        self._listener = secure
        await super().serve(secure, task_status=task_status)

    async def serve_connection(self, stream: anyio.abc.ByteStream) -> None:
        """Serve one TLS connection with the role its client certificate carries."""
        peer = peer_address(stream)
        try:
            der = stream.extra(TLSAttribute.peer_certificate_binary, None)
            if der is None:
                raise CertificateError("it sent no client certificate")
            role = certificate_role(der)
        except CertificateError as error:
            _log.warning("Modbus/TCP Security: closed the connection of %s: %s", peer, error)
            await stream.aclose()
            return
        if role is None and self.rules.default_role is None:
            _log.warning(
                "Modbus/TCP Security: the certificate of %s carries no role (extension %s) "
                "and there is no default role: every request will be refused",
                peer,
                ROLE_OID,
            )
        token = _CLIENT.set(_Client(peer, role))
        try:
            await super().serve_connection(stream)
        finally:
            _CLIENT.reset(token)

    def _permits(self) -> Permits:
        client = _CLIENT.get(None)
        rules = self.rules
        if client is None:
            return lambda adu: False
        role = client.role
        return lambda adu: rules.refusal(role, adu.unit, adu.pdu) is None

    async def _respond(self, adu: Adu) -> _Outgoing | None:
        client = _CLIENT.get(None)
        if client is None:  # a connection that came in without TLS: refuse everything
            client = _Client("a client", None)
        refusal = self.rules.refusal(client.role, adu.unit, adu.pdu)
        if refusal is None:
            return await super()._respond(adu)
        self.denied += 1
        _log.log(
            logging.DEBUG if client.warned else logging.WARNING,
            "Modbus/TCP Security: refused a request of %s (role %s) to unit %d: %s",
            client.peer,
            "none" if client.role is None else repr(client.role),
            adu.unit,
            refusal,
        )
        client.warned = True
        return self._sent(adu, encode_exception(adu.pdu[0], ExceptionCode.ILLEGAL_FUNCTION))
