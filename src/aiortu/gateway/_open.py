"""`gateway(...)`: open the lines (or take running masters), listen, serve until the block ends."""

from __future__ import annotations

import contextlib
import functools
import ssl
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Final

import anyio
import anyio.abc

from aiortu.core.machines import SAFE_TO_REPEAT
from aiortu.errors import InvalidValue
from aiortu.gateway._lines import GatewayLine, check_lines
from aiortu.gateway._metrics import parse_metrics_url, serve_metrics
from aiortu.gateway._server import (
    DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS,
    DEFAULT_MAX_IN_FLIGHT,
    Gateway,
)
from aiortu.gateway._stats import DEFAULT_CLIENT_STATISTICS
from aiortu.master import Master, open_master
from aiortu.transport import (
    MODBUS_TCP_SCHEME,
    MODBUS_UDP_SCHEME,
    TCP_SCHEME,
    TLS_SCHEME,
    WRITE_FUNCTION_CODES,
    DatagramListener,
    RoleRules,
    TlsListener,
    listen_tcp,
    listen_udp,
    listen_unix,
    listening_address,
    load_rules,
    parse_listen_url,
    parse_unix_url,
    push_listener,
    pushed_listener,
    remove_socket,
)

_SCHEMES = (MODBUS_TCP_SCHEME, MODBUS_UDP_SCHEME, TCP_SCHEME, TLS_SCHEME)
_HANDSHAKE_TIMEOUT = 10.0  # seconds a TLS client has to finish its handshake

__all__ = ("DEFAULT_RETRIES", "DEFAULT_TIMEOUT", "REPEATED_CODES", "Listen", "gateway")

DEFAULT_TIMEOUT = 0.3
"""The response timeout of a line the gateway opens, unless told otherwise: a unit that does
not answer costs 2 x (0.3 s + the request's wire time) + the 0.1 s late-reply guard, about
0.72 s at 9600 baud, within the 1 s a client such as mbpoll waits by default."""

DEFAULT_RETRIES = 1
"""Extra attempts of a request in [`REPEATED_CODES`][aiortu.gateway.REPEATED_CODES], unless told
otherwise; see [`DEFAULT_TIMEOUT`][aiortu.gateway.DEFAULT_TIMEOUT]."""

REPEATED_CODES: Final = frozenset(
    code for code in SAFE_TO_REPEAT if code not in WRITE_FUNCTION_CODES
)
"""The function codes the master of a line the gateway opens repeats after a failed attempt,
unless told otherwise (`repeatable`): the reads of
[`SAFE_TO_REPEAT`][aiortu.core.machines.SAFE_TO_REPEAT]. A write is sent once: a timed-out
write may have been done, and its client, which sees 0B, decides whether to send it again."""


@dataclass(frozen=True, slots=True)
class Listen:
    """A listen URL, the priority of its connections (lower values are served first) and its
    access rules.

    `tcp://host:port` serves Modbus TCP, `udp://host:port` Modbus UDP (each source address a
    connection of its own, answered at that address), `rtu+tcp://host:port` RTU frames over TCP
    (as a serial device server sends them), `unix:PATH` Modbus TCP on a Unix socket,
    `tls://host:port` Modbus/TCP Security (mutual TLS: give [`gateway`][aiortu.gateway.gateway]
    the server context); port 0 asks for a free port.

    `rules` are [`RoleRules`][aiortu.transport.RoleRules] or the path of a rule file
    ([`load_rules`][aiortu.transport.load_rules]): a request they refuse gets exception 01. Every
    client of a listener without certificates gets the rule of their `default_role`; a `tls://`
    client the rule of its certificate's role. None (not allowed for `tls://`): every request
    is forwarded."""

    url: str
    priority: int = 0
    rules: RoleRules | str | Path | None = None


def _listen(item: str | Listen) -> Listen:
    listen = item if isinstance(item, Listen) else Listen(item)
    if type(listen.priority) is not int:
        raise InvalidValue("priority", listen.priority, "an int (lower values go first)")
    # parse_listen_url raises for a bad URL, before anything is opened.
    unix = parse_unix_url(listen.url) is not None
    tls = not unix and parse_listen_url(listen.url, _SCHEMES).scheme == TLS_SCHEME
    if tls and listen.rules is None:
        raise InvalidValue(
            "rules", None, "given", message=f"{listen.url}: a tls:// listener needs rules"
        )
    if isinstance(listen.rules, (str, Path)):
        listen = replace(listen, rules=load_rules(listen.rules))
    elif listen.rules is not None and not isinstance(listen.rules, RoleRules):
        raise InvalidValue("rules", listen.rules, "RoleRules or the path of a rule file")
    return listen


def _lines(
    ports: str | Master | Sequence[GatewayLine], options: dict[str, Any]
) -> list[GatewayLine]:
    if isinstance(ports, (str, Master)):
        lines = [GatewayLine(ports)]
    else:
        lines = list(ports)
        if not all(isinstance(line, GatewayLine) for line in lines):
            raise InvalidValue("lines", ports, "a port name, a Master or a list of GatewayLine")
    check_lines(lines)
    if options and any(isinstance(line.port, Master) for line in lines):
        raise InvalidValue("master_options", sorted(options), "none with a Master given")
    return lines


async def _open_lines(
    stack: contextlib.AsyncExitStack, lines: list[GatewayLine], options: dict[str, Any]
) -> list[GatewayLine]:
    """The lines with a running master each: those given, and those opened with `options`."""
    options.setdefault("fail_fast_offline", True)
    options.setdefault("reconnect_fail_fast", True)
    options.setdefault("timeout", DEFAULT_TIMEOUT)
    options.setdefault("retries", DEFAULT_RETRIES)
    options.setdefault("repeatable", REPEATED_CODES)
    opened = []
    for line in lines:
        master = line.port
        if not isinstance(master, Master):
            own = {**options, **line.options}
            master = await stack.enter_async_context(open_master(master, **own))
        opened.append(GatewayLine(master, line.units, line.label))
    return opened


async def _listener(
    stack: contextlib.AsyncExitStack, url: str, tls: ssl.SSLContext | None = None
) -> anyio.abc.Listener[anyio.abc.ByteStream]:
    unix = parse_unix_url(url)
    if unix is not None:
        listener = await listen_unix(unix, url)
        stack.callback(remove_socket, unix.path)
    elif url.startswith("http://"):
        where = parse_metrics_url(url)
        listener = await listen_tcp(where.host, where.port, url=url)
    else:
        address = parse_listen_url(url, _SCHEMES)
        if address.scheme == MODBUS_UDP_SCHEME:
            sock = await listen_udp(address.host, address.port, url=url)
            listener = DatagramListener(sock, url)
        else:
            listener = await listen_tcp(address.host, address.port, url=url)
        if address.scheme == TLS_SCHEME:
            if tls is None:
                raise InvalidValue(
                    "certfile", None, "given", message=f"{url}: give certfile, keyfile and cafile"
                )
            if push_listener(listener):  # read from the loop's callback
                listener = pushed_listener(
                    listener, tls, standard_compatible=False, handshake_timeout=_HANDSHAKE_TIMEOUT
                )
            else:
                listener = TlsListener(
                    listener, tls, standard_compatible=False, handshake_timeout=_HANDSHAKE_TIMEOUT
                )
        elif address.scheme == MODBUS_TCP_SCHEME and push_listener(listener):
            listener = pushed_listener(listener)  # read from the loop's callback
    stack.push_async_callback(listener.aclose)
    return listener


def _rtu_framing(url: str) -> bool:
    return parse_unix_url(url) is None and parse_listen_url(url, _SCHEMES).scheme == TCP_SCHEME


@contextlib.asynccontextmanager
async def gateway(
    serial_port_or_master: str | Master | Sequence[GatewayLine],
    listen: Sequence[str | Listen] = (),
    *,
    max_in_flight: int = DEFAULT_MAX_IN_FLIGHT,
    max_connections: int = DEFAULT_MAX_CONNECTIONS,
    idle_timeout: float = DEFAULT_IDLE_TIMEOUT,
    default_unit: int | None = None,
    coalesce: bool = True,
    cache_ms: float = 0,
    clock: Callable[[], float] | None = None,
    metrics: str | None = None,
    client_statistics: int = DEFAULT_CLIENT_STATISTICS,
    tls: ssl.SSLContext | None = None,
    **master_options: Any,
) -> AsyncIterator[Gateway]:
    """Share serial lines with network clients: yield a running
    [`Gateway`][aiortu.gateway.Gateway] listening on every URL in `listen`.

    `serial_port_or_master` is a port name for [`open_master`][aiortu.master.open_master] (with
    `master_options`; `fail_fast_offline` and `reconnect_fail_fast` default to true here, so that
    clients get exceptions 0B and 0A at once, `timeout` and `retries` to
    [`DEFAULT_TIMEOUT`][aiortu.gateway.DEFAULT_TIMEOUT] and
    [`DEFAULT_RETRIES`][aiortu.gateway.DEFAULT_RETRIES], so that a unit that does not answer
    gets 0B within a client's 1 s, and `repeatable` to
    [`REPEATED_CODES`][aiortu.gateway.REPEATED_CODES]: writes are sent once), a running
    [`Master`][aiortu.master.Master], used as it is, or several
    [`GatewayLine`][aiortu.gateway.GatewayLine]s, each with its unit range.
    With `metrics` (`http://127.0.0.1:9102/metrics`), the statistics are served there as
    Prometheus text, from [`metrics_address`][aiortu.gateway.Gateway.metrics_address]. `tls` is
    the server context of the `tls://` listeners
    ([`server_tls_context`][aiortu.transport.server_tls_context]). The other arguments are
    [`Gateway`][aiortu.gateway.Gateway]'s.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a listen URL that is not
    `tcp://host:port`, `udp://host:port`, `rtu+tcp://host:port`, `tls://host:port` or
    `unix:PATH`, a `tls://` one without rules or `tls`, or lines whose unit ranges overlap,
    [`ConfigError`][aiortu.errors.ConfigError] for a bad rule file, and
    [`PortError`][aiortu.errors.PortError]s when a port cannot be opened.
    """
    listens = [_listen(item) for item in listen]
    lines = _lines(serial_port_or_master, master_options)
    where = parse_metrics_url(metrics) if metrics is not None else None
    async with contextlib.AsyncExitStack() as stack:
        # Listeners first: an address that cannot be had fails before any line is opened (and
        # before any task group, which would wrap the error).
        listeners = [(await _listener(stack, item.url, tls), item) for item in listens]
        http = None if where is None or metrics is None else await _listener(stack, metrics)
        server = Gateway(
            await _open_lines(stack, lines, master_options),
            max_in_flight=max_in_flight,
            max_connections=max_connections,
            idle_timeout=idle_timeout,
            default_unit=default_unit,
            coalesce=coalesce,
            cache_ms=cache_ms,
            clock=clock,
            client_statistics=client_statistics,
        )
        tasks = await stack.enter_async_context(anyio.create_task_group())
        stack.callback(tasks.cancel_scope.cancel)
        for listener, item in listeners:
            assert item.rules is None or isinstance(item.rules, RoleRules)
            serve = functools.partial(
                server.serve,
                listener,
                priority=item.priority,
                rtu_framing=_rtu_framing(item.url),
                rules=item.rules,
            )
            await tasks.start(serve)
        if http is not None and where is not None:
            server.metrics_address = listening_address(http)
            tasks.start_soon(serve_metrics, http, where.path, server.statistics.prometheus)
        yield server
