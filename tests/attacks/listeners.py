"""Every listener of the project, started on loopback for the attack tests, and the clients
that attack them.

`listeners(directory)` runs the slave's servers (`serve` on tcp://, tls://, udp://,
rtu+tcp:// and ascii+tcp://) and the gateway's (`--listen` tcp://, tls://, udp://,
rtu+tcp://, unix: and the metrics responder) in one task group, each on a free port, with a
small connection limit and idle timeout so that an attack reaches them at once. Each is a
`Target`: how to reach it, a good request in its framing and the reply it must get. The
attack clients are blocking sockets, run in a worker thread (`anyio.to_thread`), so that the
servers' event loop is never blocked by them.
"""

from __future__ import annotations

import logging
import socket
import ssl
from collections.abc import AsyncIterator, Iterator
from contextlib import AsyncExitStack, asynccontextmanager, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiortu.core.ascii import encode_ascii_frame
from aiortu.core.mbap import encode_adu
from aiortu.core.rtu import encode_frame
from aiortu.gateway import Listen
from aiortu.slave import MemoryStore, serve
from aiortu.transport import AccessRule, RoleRules, server_tls_context
from tests.gateway.helpers import line
from tests.slave.tcp_helpers import UNIT
from tests.transport.certificates import Authority

__all__ = (
    "MAX_CONNECTIONS",
    "READ",
    "READ_ALL",
    "Records",
    "Target",
    "ask",
    "client_context",
    "listener",
    "listeners",
    "open_client",
    "records",
)

MAX_CONNECTIONS = 8
"""The connection limit of every listener under attack."""
IDLE_TIMEOUT = 0.5
"""Seconds of silence after which the listeners with an idle timeout close a connection."""
READ = bytes.fromhex("03 0000 0001")
"""The good request: one holding register of unit 17, which holds 0x1234."""
_ANSWER = bytes.fromhex("03 02 1234")
RULES = RoleRules({"operator": AccessRule(frozenset(range(1, 128)))})
READ_ALL = bytes.fromhex("03 0000 007D")
"""A request whose reply is 21 times its size: all 125 holding registers."""


def _store() -> MemoryStore:
    return MemoryStore(holding_registers={0: [0x1234] + [0] * 124})


@dataclass
class Target:
    """One listener: `kind` tcp, tls, udp or unix; `framing` mbap, rtu, ascii or http."""

    name: str
    kind: str
    framing: str
    address: Any
    server: Any
    client_context: ssl.SSLContext | None = None
    max_connections: int = MAX_CONNECTIONS

    def request(self, transaction_id: int = 1, pdu: bytes = READ) -> bytes:
        """A good request in this listener's framing (`pdu` the good read by default)."""
        if self.framing == "rtu":
            return encode_frame(UNIT, pdu)
        if self.framing == "ascii":
            return encode_ascii_frame(UNIT, pdu)
        if self.framing == "http":
            return b"GET /metrics HTTP/1.0\r\n\r\n"
        return encode_adu(transaction_id, UNIT, pdu)

    def reply(self, transaction_id: int = 1) -> bytes:
        """What the good request gets (for http: the start of the status line)."""
        if self.framing == "rtu":
            return encode_frame(UNIT, _ANSWER)
        if self.framing == "ascii":
            return encode_ascii_frame(UNIT, _ANSWER)
        if self.framing == "http":
            return b"HTTP/1.1 200 OK"
        return encode_adu(transaction_id, UNIT, _ANSWER)

    @property
    def stream(self) -> bool:
        return self.kind != "udp"


def open_client(target: Target, timeout: float = 5.0, **bind: Any) -> socket.socket:
    """A connected blocking socket to `target` (for tls, after the handshake); `bind` takes
    `source` (a local host) for TCP and UDP, and `receive_buffer` (bytes)."""
    if target.kind == "unix":
        sock = socket.socket(socket.AF_UNIX)
    else:
        kind = socket.SOCK_DGRAM if target.kind == "udp" else socket.SOCK_STREAM
        sock = socket.socket(socket.AF_INET, kind)
        if "source" in bind:
            sock.bind((bind["source"], 0))
    sock.settimeout(timeout)
    if "receive_buffer" in bind:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, bind["receive_buffer"])
    try:
        sock.connect(target.address)
        if target.kind == "tls":
            assert target.client_context is not None
            return target.client_context.wrap_socket(sock, server_hostname="localhost")
    except BaseException:
        sock.close()
        raise
    return sock


def ask(target: Target, timeout: float = 10.0, **bind: Any) -> bytes:
    """Send the good request on a new connection; return the reply (what was read until it
    was whole, the peer closed or `timeout` passed). Over UDP the request is sent again every
    0.5 s until answered, as a Modbus UDP client retries: a flood may fill the server's
    socket buffer, and the kernel drops what comes then."""
    expected = target.reply()
    if target.kind == "udp":
        with open_client(target, 0.5, **bind) as sock:
            for _ in range(int(timeout / 0.5)):
                sock.send(target.request())
                try:
                    return sock.recv(65536)
                except TimeoutError:
                    continue
        return b""
    with open_client(target, timeout, **bind) as sock:
        sock.sendall(target.request())
        data = b""
        try:
            while len(data) < len(expected) and (chunk := sock.recv(65536)):
                data += chunk
        except (TimeoutError, ConnectionError):
            pass
        return data


@dataclass
class Records(logging.Handler):
    """The library's log records while attached (see `records`)."""

    taken: list[logging.LogRecord] = field(default_factory=list)

    def __post_init__(self) -> None:
        logging.Handler.__init__(self, logging.DEBUG)

    def __hash__(self) -> int:
        return id(self)

    def emit(self, record: logging.LogRecord) -> None:
        self.taken.append(record)

    def at_least(self, level: int) -> list[logging.LogRecord]:
        return [each for each in self.taken if each.levelno >= level]

    @property
    def tracebacks(self) -> list[logging.LogRecord]:
        return [each for each in self.taken if each.exc_info]


@contextmanager
def records() -> Iterator[Records]:
    """Every record of the `aiortu` loggers while the block runs (debug ones included)."""
    handler = Records()
    logger = logging.getLogger("aiortu")
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


_Contexts = tuple[ssl.SSLContext, ssl.SSLContext, dict[str, Path]]


@contextmanager
def _tls_contexts(directory: Path) -> Iterator[_Contexts]:
    """The server's TLS context, an operator's client context, and the server's files."""
    ca = Authority(directory)
    server = ca.issue("server", server=True)
    ca.issue("operator", role="operator")  # read back by client_context
    files = {"certfile": server.certfile, "keyfile": server.keyfile, "cafile": ca.cafile}
    yield server_tls_context(**files), client_context(directory), files


def client_context(directory: Path) -> ssl.SSLContext:
    """The client context of the operator whose certificate `listeners` left in `directory`."""
    client = ssl.create_default_context(cafile=str(directory / "aiortu-test-CA.pem"))
    client.load_cert_chain(directory / "operator.crt", directory / "operator.key")
    return client


SLAVE = ("tcp", "tls", "udp", "rtu+tcp", "ascii+tcp")
GATEWAY = ("tcp", "tls", "udp", "rtu+tcp", "unix", "metrics")
NAMES = (*(f"serve {scheme}" for scheme in SLAVE), *(f"gateway {scheme}" for scheme in GATEWAY))
"""Every listener: the slave's `serve(URL)` and the gateway's `--listen URL` (and metrics)."""
STREAMS = tuple(name for name in NAMES if not name.endswith("udp"))
MODBUS_STREAMS = tuple(name for name in STREAMS if name != "gateway metrics")
_KINDS = {"tcp": ("tcp", "mbap"), "tls": ("tls", "mbap"), "udp": ("udp", "mbap"),
          "rtu+tcp": ("tcp", "rtu"), "ascii+tcp": ("tcp", "ascii"), "unix": ("unix", "mbap"),
          "metrics": ("tcp", "http")}  # fmt: skip


@asynccontextmanager
async def listeners(
    directory: Path, names: tuple[str, ...] = NAMES, max_connections: int = MAX_CONNECTIONS
) -> AsyncIterator[dict[str, Target]]:
    """The listeners `names` (see `NAMES`), each on a free port of 127.0.0.1 or a socket in
    `directory`, with `max_connections` each (see the module docstring)."""
    with _tls_contexts(directory) as (server_context, client_context, files):
        async with AsyncExitStack() as stack:
            targets: dict[str, Target] = {}
            for name in names:
                who, scheme = name.split()
                kind, framing = _KINDS[scheme]
                context = client_context if kind == "tls" else None
                if who == "serve":
                    address, server = await _serve(stack, scheme, files, max_connections)
                else:
                    address, server = await _gateway(
                        stack, scheme, directory, server_context, max_connections
                    )
                targets[name] = Target(
                    name, kind, framing, address, server, context,
                    max_connections=8 if scheme == "metrics" else max_connections,
                )  # fmt: skip
            yield targets


@asynccontextmanager
async def listener(directory: Path, name: str) -> AsyncIterator[Target]:
    """The one listener `name` (see `listeners`)."""
    async with listeners(directory, (name,)) as targets:
        yield targets[name]


async def _serve(
    stack: AsyncExitStack, scheme: str, files: dict[str, Path], max_connections: int
) -> tuple[Any, Any]:
    options: dict[str, Any] = {}
    if scheme != "udp":
        options["max_connections"] = max_connections
        options["idle_timeout"] = IDLE_TIMEOUT
    if scheme == "tls":
        options.update(files, rules=RULES)
    server = await stack.enter_async_context(
        serve(f"{scheme}://127.0.0.1:0", {UNIT: _store()}, **options)
    )
    return server.local_address, server


async def _gateway(
    stack: AsyncExitStack,
    scheme: str,
    directory: Path,
    context: ssl.SSLContext,
    max_connections: int,
) -> tuple[Any, Any]:
    path = str(directory / "gateway.sock")
    url: str | Listen = {"unix": f"unix:{path}", "metrics": "tcp://127.0.0.1:0"}.get(
        scheme, f"{scheme}://127.0.0.1:0"
    )
    if scheme == "tls":
        url = Listen(str(url), rules=RULES)
    bench = await stack.enter_async_context(
        line(
            {UNIT: _store()},
            listen=(url,),
            tls=context,
            max_connections=max_connections,
            idle_timeout=IDLE_TIMEOUT,
            metrics="http://127.0.0.1:0/metrics" if scheme == "metrics" else None,
        )
    )
    gateway = bench.gateway
    if scheme == "unix":
        return path, gateway
    if scheme == "metrics":
        return gateway.metrics_address, gateway
    return gateway.local_addresses[0], gateway
