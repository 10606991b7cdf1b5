"""`--metrics`: the gateway's statistics as Prometheus text, over a tiny HTTP responder.

It answers `GET PATH` (the path of the metrics URL) with the text exposition format and
anything else with 404, one request per connection, then closes it; at most
`MAX_METRICS_CONNECTIONS` at once (a scraper needs one), through the same accept loop as every
listener ([`serve_listener`][aiortu.transport.serve_listener]). The format is written
directly (see [`GatewayStatistics`][aiortu.gateway.GatewayStatistics]): no dependency.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.errors import InvalidValue
from aiortu.transport import ConnectionLimit, serve_listener

__all__ = ("MAX_METRICS_CONNECTIONS", "MetricsAddress", "parse_metrics_url", "serve_metrics")

_log = get_logger(__name__)

MAX_METRICS_CONNECTIONS = 8
"""Metrics connections served at once; more are closed at once."""

_FORM = "http://HOST:PORT/PATH"
_MAX_REQUEST = 8192
_REQUEST_TIMEOUT = 5.0
_CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


@dataclass(frozen=True, slots=True)
class MetricsAddress:
    """Where the metrics are served: a host to bind, a port (0: a free one) and a path."""

    host: str
    port: int
    path: str


def parse_metrics_url(url: str) -> MetricsAddress:
    """Parse `http://HOST:PORT/PATH`; raises [`InvalidValue`][aiortu.errors.InvalidValue]."""
    scheme, separator, rest = url.partition("://")
    netloc, slash, path = rest.partition("/")
    host, colon, port = netloc.rpartition(":")
    host = host.strip("[]")
    if scheme != "http" or not separator or not colon or not host:
        raise InvalidValue("metrics", url, _FORM, "expected an http:// URL with a host and port")
    if not (port.isascii() and port.isdigit() and int(port) <= 65535):
        raise InvalidValue("metrics", url, _FORM, f"the port {port!r} is not in 0..65535")
    return MetricsAddress(host, int(port), slash + path or "/metrics")


async def serve_metrics(
    listener: anyio.abc.Listener[anyio.abc.ByteStream], path: str, text: Callable[[], str]
) -> None:
    """Answer `GET path` with `text()` on every connection of `listener`, until cancelled."""

    async def answer(stream: anyio.abc.ByteStream) -> None:
        async with stream:
            request = b""
            with anyio.move_on_after(_REQUEST_TIMEOUT):
                while b"\r\n\r\n" not in request and len(request) < _MAX_REQUEST:
                    try:
                        request += await stream.receive()
                    except (anyio.EndOfStream, anyio.BrokenResourceError):
                        return
            words = request.split(b"\r\n", 1)[0].split()
            if (
                len(words) == 3
                and words[0] == b"GET"
                and words[1].split(b"?")[0].decode("latin-1") == path
            ):
                body, status = text().encode(), "200 OK"
            else:
                body, status = b"not found\n", "404 Not Found"
            head = (
                f"HTTP/1.1 {status}\r\nContent-Type: {_CONTENT_TYPE}\r\n"
                f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
            )
            try:
                await stream.send(head.encode() + body)
            except (anyio.BrokenResourceError, anyio.ClosedResourceError):
                _log.debug("gateway metrics: the client left before the reply")

    await serve_listener(
        listener, answer, ConnectionLimit("gateway metrics", MAX_METRICS_CONNECTIONS)
    )
