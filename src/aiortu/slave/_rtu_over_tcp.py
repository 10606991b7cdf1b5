"""RTU framing over TCP, listening: each connection a line of its own, served by its own
[`Slave`][aiortu.slave.Slave], for serial device servers that connect in."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.core.model import AsyncDataStore, DataStore, Table
from aiortu.core.rtu import TimingMode
from aiortu.core.serial import LineSettings
from aiortu.errors import ConnectionLost, InvalidValue
from aiortu.slave._dispatch import AfterHook, BeforeHook
from aiortu.slave._handlers import Handler
from aiortu.slave._routes import RangeHandler
from aiortu.slave._slave import Slave, TraceCallback
from aiortu.slave._tcp_server import DEFAULT_MAX_CONNECTIONS
from aiortu.transport import AcceptCounters, ConnectionLimit, listening_address, serve_listener

__all__ = ("RtuOverTcpServer",)

_log = get_logger(__name__)

_UNIT_RANGE = range(1, 248)
_FUNCTION_CODE_RANGE = range(1, 128)


class RtuOverTcpServer:
    """RTU framing over TCP, listening: each connection is a line served by its own
    [`Slave`][aiortu.slave.Slave] (`frame_gap` 0, its own machine and counters), all on the same
    `units`' stores. For serial device servers that connect in.

    [`set_handler`][aiortu.slave.RtuOverTcpServer.set_handler],
    [`route`][aiortu.slave.RtuOverTcpServer.route],
    [`before_request`][aiortu.slave.RtuOverTcpServer.before_request] and
    [`after_request`][aiortu.slave.RtuOverTcpServer.after_request] apply to the lines connected now
    and to every later one. At most `max_connections` lines at once; more are closed at once. There
    is no idle timeout: a line is quiet whenever no master polls.
    """

    def __init__(
        self,
        units: Mapping[int, DataStore | AsyncDataStore],
        settings: LineSettings | None = None,
        *,
        timing: TimingMode | str = TimingMode.TOLERANT,
        handlers: Mapping[int, Handler] | None = None,
        trace: TraceCallback | None = None,
        max_connections: int = DEFAULT_MAX_CONNECTIONS,
    ) -> None:
        if type(max_connections) is not int or max_connections < 1:
            raise InvalidValue("max_connections", max_connections, "an int of at least 1")
        self.units: dict[int, DataStore | AsyncDataStore] = dict(units)
        """The data store of each unit served."""
        self.slaves: set[Slave] = set()
        """The slave of each line connected now."""
        self.counters = AcceptCounters()
        """The lines accepted, and those closed at once for the limit."""
        self._limit = ConnectionLimit("RTU over TCP", max_connections, self.counters)
        self.local_address: tuple[str, int] | None = None
        """The host and port [`serve`][aiortu.slave.RtuOverTcpServer.serve] listens on, once it
        does."""
        self.connection_error: Exception | None = None
        """Why [`serve`][aiortu.slave.RtuOverTcpServer.serve] stopped, when the listener failed."""
        self._settings = settings
        self._timing = timing
        self._trace = trace
        self._setup: list[Callable[[Slave], object]] = []
        self._stopped = anyio.Event()
        for unit in self.units:
            if unit not in _UNIT_RANGE:
                raise InvalidValue("unit", unit, _UNIT_RANGE)
        for function_code, handler in (handlers or {}).items():
            if function_code not in _FUNCTION_CODE_RANGE:
                raise InvalidValue("function_code", function_code, _FUNCTION_CODE_RANGE)
            self.set_handler(function_code, handler)

    @property
    def max_connections(self) -> int:
        """Lines served at once; more are closed at once (the refusals of a burst logged
        once)."""
        return self._limit.max_connections

    @max_connections.setter
    def max_connections(self, value: int) -> None:
        self._limit.max_connections = value

    @property
    def port(self) -> int:
        """The port [`serve`][aiortu.slave.RtuOverTcpServer.serve] listens on (useful after asking
        for port 0)."""
        if self.local_address is None:
            raise RuntimeError("the server is not listening yet")
        return self.local_address[1]

    def _apply(self, call: Callable[[Slave], object]) -> None:
        self._setup.append(call)
        for slave in self.slaves:
            call(slave)

    def set_handler(self, function_code: int, handler: Handler | None) -> None:
        """As [`Slave.set_handler`][aiortu.slave.Slave.set_handler], on every line."""
        self._apply(lambda slave: slave.set_handler(function_code, handler))

    def route(self, table: Table | str, addresses: range, handler: RangeHandler) -> None:
        """As [`Slave.route`][aiortu.slave.Slave.route] (every unit), on every line."""
        self._apply(lambda slave: slave.route(table, addresses, handler))

    def before_request(self, hook: BeforeHook) -> Callable[[], None]:
        """As [`Slave.before_request`][aiortu.slave.Slave.before_request], on every line; returns
        the remover."""
        return self._hook(lambda slave: slave.before_request(hook))

    def after_request(self, hook: AfterHook) -> Callable[[], None]:
        """As [`Slave.after_request`][aiortu.slave.Slave.after_request], on every line; returns the
        remover."""
        return self._hook(lambda slave: slave.after_request(hook))

    def _hook(self, add: Callable[[Slave], Callable[[], None]]) -> Callable[[], None]:
        removers: list[Callable[[], None]] = []

        def add_to(slave: Slave) -> None:
            removers.append(add(slave))

        def remove() -> None:
            if add_to in self._setup:
                self._setup.remove(add_to)
            for remover in removers:
                remover()

        self._apply(add_to)
        return remove

    async def wait_stopped(self) -> None:
        """Wait until [`serve`][aiortu.slave.RtuOverTcpServer.serve] has ended (the listener failed
        or closed)."""
        await self._stopped.wait()

    async def serve(
        self,
        listener: anyio.abc.Listener[anyio.abc.ByteStream],
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Accept lines from `listener` and serve each, until cancelled."""
        try:
            self.local_address = listening_address(listener)
            task_status.started()
            await serve_listener(listener, self.serve_connection, self._limit)
        except Exception as error:
            self.connection_error = error
            _log.error("RTU over TCP: the listener failed: %s", error)
        finally:
            self._stopped.set()

    async def serve_connection(self, stream: anyio.abc.ByteStream) -> None:
        """Serve one line until it closes."""
        slave = Slave(
            stream, self.units, self._settings, frame_gap=0, timing=self._timing, trace=self._trace
        )
        for call in self._setup:
            call(slave)
        self.slaves.add(slave)
        try:
            await slave.serve()
        except ConnectionLost:
            pass
        except Exception:
            # One line's failure never ends the others, nor the server.
            _log.exception("RTU over TCP: a line failed; it is closed")
        finally:
            self.slaves.discard(slave)
            await stream.aclose()
