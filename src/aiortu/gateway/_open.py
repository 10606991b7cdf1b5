"""`gateway(...)`: open the line (or take a running master), listen, serve until the block ends."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass
from typing import Any

import anyio

from aiortu.errors import InvalidValue
from aiortu.gateway._server import (
    DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS,
    DEFAULT_MAX_IN_FLIGHT,
    Gateway,
)
from aiortu.master import Master, open_master
from aiortu.transport import MODBUS_TCP_SCHEME, listen_tcp, parse_listen_url

__all__ = ("Listen", "gateway")


@dataclass(frozen=True, slots=True)
class Listen:
    """A listen URL and the priority of its connections: lower values are served first.

    `tcp://host:port` serves Modbus TCP, `rtu+tcp://host:port` RTU frames over TCP (as a
    serial device server sends them); port 0 asks for a free port."""

    url: str
    priority: int = 0


def _listen(item: str | Listen) -> Listen:
    listen = item if isinstance(item, Listen) else Listen(item)
    if type(listen.priority) is not int:
        raise InvalidValue("priority", listen.priority, "an int (lower values go first)")
    parse_listen_url(listen.url)  # raises for a bad one, before anything is opened
    return listen


@contextlib.asynccontextmanager
async def gateway(
    serial_port_or_master: str | Master,
    listen: Sequence[str | Listen] = (),
    *,
    max_in_flight: int = DEFAULT_MAX_IN_FLIGHT,
    max_connections: int = DEFAULT_MAX_CONNECTIONS,
    idle_timeout: float = DEFAULT_IDLE_TIMEOUT,
    default_unit: int | None = None,
    coalesce: bool = True,
    **master_options: Any,
) -> AsyncIterator[Gateway]:
    """Share one serial line with network clients: yield a running
    [`Gateway`][aiortu.gateway.Gateway] listening on every URL in `listen`.

    `serial_port_or_master` is a port name for [`open_master`][aiortu.master.open_master] (with
    `master_options`; `fail_fast_offline` and `reconnect_fail_fast` default to true here, so that
    clients get exceptions 0B and 0A at once) or a running [`Master`][aiortu.master.Master],
    used as it is. The other arguments are [`Gateway`][aiortu.gateway.Gateway]'s.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a listen URL that is not
    `tcp://host:port` or `rtu+tcp://host:port`, and [`PortError`][aiortu.errors.PortError]s
    when a port cannot be opened.
    """
    listens = [_listen(item) for item in listen]
    async with contextlib.AsyncExitStack() as stack:
        if isinstance(serial_port_or_master, Master):
            if master_options:
                raise InvalidValue(
                    "master_options", sorted(master_options), "none with a Master given"
                )
            master = serial_port_or_master
        else:
            master_options.setdefault("fail_fast_offline", True)
            master_options.setdefault("reconnect_fail_fast", True)
            master = await stack.enter_async_context(
                open_master(serial_port_or_master, **master_options)
            )
        server = Gateway(
            master,
            max_in_flight=max_in_flight,
            max_connections=max_connections,
            idle_timeout=idle_timeout,
            default_unit=default_unit,
            coalesce=coalesce,
        )
        listeners = []
        for item in listens:
            address = parse_listen_url(item.url)
            listeners.append((await listen_tcp(address.host, address.port, url=item.url), item))
        tasks = await stack.enter_async_context(anyio.create_task_group())
        stack.callback(tasks.cancel_scope.cancel)
        await tasks.start(server.run)
        for listener, item in listeners:
            rtu_framing = parse_listen_url(item.url).scheme != MODBUS_TCP_SCHEME
            serve = functools.partial(
                server.serve, listener, priority=item.priority, rtu_framing=rtu_framing
            )
            await tasks.start(serve)
        yield server
