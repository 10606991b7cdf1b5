"""The slave: serves one or many unit addresses on one line from data stores.

:class:`Slave` takes any byte stream (a serial port, a TCP connection to a serial device
server, a virtual line) and a mapping of unit addresses to data stores::

    store = aiortu.MemoryStore(holding_registers={0x6B: 3})
    async with aiortu.Slave(stream, {17: store}):
        ...                                   # the slave serves in the background

or ``await slave.serve()`` to serve in the current task. :func:`serve` opens a port or a
URL first. One line may carry a whole bus of simulated units.

Each frame goes through the core's :class:`~aiortu.core.slave_machine.SlaveMachine`,
which decides what the spec says: frames for other units are dropped and counted, frames
with a bad CRC never reach it (the link discards and counts them), broadcasts are
executed by every unit and never answered, and exceptions come in the spec's order
(01, 03, 02, 04). A request is dispatched by function code to a handler (see
:mod:`aiortu.slave_handlers`); users register their own with :meth:`Slave.set_handler`,
including for the user-defined codes 65-72 and 100-110, which arrive as
:class:`~aiortu.core.pdu.RawPDU`. A handler that raises
:class:`~aiortu.errors.ExceptionResponse` answers with its code; any other error answers
04, is logged, and the slave goes on serving. The reply goes out after ``frame_gap`` of
silence on the line (t3.5 by default; the link keeps it).
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from types import TracebackType
from typing import Any, Self

import anyio
import anyio.abc

from aiortu.core.codes import EXCEPTION_BIT, ExceptionCode
from aiortu.core.data_model import DataStore
from aiortu.core.frame import encode_frame
from aiortu.core.pdu import Request, decode_request
from aiortu.core.receiver import DiscardReason, FrameReceived, Role, TimingMode
from aiortu.core.slave_machine import SerialLineCounters, SlaveMachine
from aiortu.core.timing import LineSettings
from aiortu.errors import ConnectionLost, ExceptionResponse, InvalidValue, MalformedPDU
from aiortu.link import Link
from aiortu.slave_handlers import BUILTIN_HANDLERS, Handler, HandlerResult, RequestContext
from aiortu.transport import open_stream

__all__ = ("Slave", "serve")

_log = logging.getLogger(__name__)

_UNIT_RANGE = range(1, 248)
_FUNCTION_CODE_RANGE = range(1, EXCEPTION_BIT)


class Slave:
    """A Modbus RTU slave on one line (see the module docstring).

    *units* maps each unit address (1..247) to its data store. *settings* are the line
    settings; *frame_gap* is the silence kept before each reply (``None`` for t3.5 of the
    settings, 0 for lines without a wire such as TCP). *timing* and *frame_silence*
    configure the receiver (see :mod:`aiortu.core.receiver`). *handlers* adds or replaces
    handlers by function code, as :meth:`set_handler` does. *clock* is the link's clock.

    Raises :class:`~aiortu.errors.InvalidValue` for a unit address outside 1..247 or a
    function code outside 1..127.
    """

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        units: Mapping[int, DataStore],
        settings: LineSettings | None = None,
        *,
        frame_gap: float | None = None,
        timing: TimingMode | str = TimingMode.TOLERANT,
        frame_silence: float | None = None,
        handlers: Mapping[int, Handler] | None = None,
        clock: Callable[[], float] = anyio.current_time,
    ) -> None:
        for unit in units:
            if unit not in _UNIT_RANGE:
                raise InvalidValue("unit", unit, _UNIT_RANGE)
        self.units: dict[int, DataStore] = dict(units)
        """The data store of each unit served."""
        self.link = Link(
            stream,
            settings,
            role=Role.SLAVE,
            units=self.units,
            timing=timing,
            frame_silence=frame_silence,
            frame_gap=frame_gap,
            clock=clock,
        )
        """The line this slave serves (its counters say what the receiver discarded)."""
        self.counters = SerialLineCounters()
        """The spec's diagnostic counters of this line."""
        self.machine = SlaveMachine(self.units, self.counters)
        """The state machine that decides what to answer."""
        self.connection_error: ConnectionLost | None = None
        """Why the background serve loop ended, when it ended because the line failed."""
        self._handlers: dict[int, Handler] = dict(BUILTIN_HANDLERS)
        for function_code, handler in (handlers or {}).items():
            self.set_handler(function_code, handler)
        self._contexts = {unit: RequestContext(unit, store) for unit, store in self.units.items()}
        self._task_group: anyio.abc.TaskGroup | None = None
        self._stopped = anyio.Event()

    # -- handlers --------------------------------------------------------------------

    def set_handler(self, function_code: int, handler: Handler | None) -> None:
        """Serve *function_code* with *handler*; ``None`` removes it (the code then gets 01).

        The handler is called as ``handler(request, context)`` with the decoded request
        (a :class:`~aiortu.core.pdu.RawPDU` for codes without a class) and a
        :class:`~aiortu.slave_handlers.RequestContext`; it returns the response PDU, or
        ``None`` to send nothing, and may be a coroutine function.
        """
        if function_code not in _FUNCTION_CODE_RANGE:
            raise InvalidValue("function_code", function_code, _FUNCTION_CODE_RANGE)
        if handler is None:
            self._handlers.pop(function_code, None)
        else:
            self._handlers[function_code] = handler

    def handler(self, function_code: int) -> Callable[[Handler], Handler]:
        """Decorator form of :meth:`set_handler`."""

        def register(handler: Handler) -> Handler:
            self.set_handler(function_code, handler)
            return handler

        return register

    @property
    def function_codes(self) -> frozenset[int]:
        """The function codes this slave serves."""
        return frozenset(self._handlers)

    # -- lifetime --------------------------------------------------------------------

    @property
    def listen_only(self) -> bool:
        """In listen-only mode requests are executed and never answered."""
        return self.machine.listen_only

    @listen_only.setter
    def listen_only(self, value: bool) -> None:
        self.machine.listen_only = value

    async def serve(self) -> None:
        """Serve until cancelled.

        Raises :class:`~aiortu.errors.ConnectionLost` when the line fails or closes.
        """
        lost: ConnectionLost | None = None
        async with self.link:
            try:
                await self._serve_frames()
            except ConnectionLost as error:
                # Raised outside the link's task group, so that it is not wrapped in an
                # ExceptionGroup on the way out.
                lost = error
        if lost is not None:
            raise lost

    async def __aenter__(self) -> Self:
        self._task_group = anyio.create_task_group()
        await self._task_group.__aenter__()
        self._task_group.start_soon(self._serve_in_background, name="aiortu slave")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:
        assert self._task_group is not None
        self._task_group.cancel_scope.cancel()
        # The body's own exception propagates as it is, not wrapped in an ExceptionGroup.
        await self._task_group.__aexit__(None, None, None)
        return None

    async def wait_stopped(self) -> None:
        """Wait until the background serve loop has ended (the line failed or closed)."""
        await self._stopped.wait()

    async def _serve_in_background(self) -> None:
        try:
            await self.serve()
        except ConnectionLost as error:
            self.connection_error = error
        finally:
            self._stopped.set()

    # -- the serve loop --------------------------------------------------------------

    async def _serve_frames(self) -> None:
        link = self.link
        machine = self.machine
        while True:
            event = await link.receive()
            if not isinstance(event, FrameReceived):
                if event.reason is DiscardReason.CRC:
                    machine.frame_corrupt()
                elif event.reason is DiscardReason.OVERFLOW:
                    machine.character_overrun()
                continue
            unit = event.frame[0]
            if not machine.frame_received(unit):
                continue
            reply = await self._answer(unit, event.frame[1:-2])
            if reply is not None and machine.should_reply:
                await link.send(encode_frame(unit, reply))
                machine.reply_sent()
            else:
                machine.no_reply()

    async def _answer(self, unit: int, pdu: bytes) -> bytes | None:
        """Check and execute one request; return the reply PDU, or None to send nothing."""
        machine = self.machine
        function_code = pdu[0]
        handler = self._handlers.get(function_code)
        request: Request | None = None
        violation: int | None = None
        if handler is not None:
            try:
                request = decode_request(pdu)
            except MalformedPDU as error:
                violation = error.exception_code
        if not machine.check_request(supported=handler is not None, violation=violation):
            return _exception_pdu(function_code, machine.exception_code)
        assert handler is not None
        try:
            if machine.broadcast:
                await self._execute_broadcast(handler, request)
                reply = None
            else:
                result = await _call(handler, request, self._contexts[unit])
                reply = None if result is None else result.encode()
        except ExceptionResponse as error:
            machine.processing_failed(error.code)
            return _exception_pdu(function_code, error.code)
        except Exception:
            _log.exception("unit %d: the handler of function 0x%02X failed", unit, function_code)
            machine.processing_failed(ExceptionCode.SERVER_DEVICE_FAILURE)
            return _exception_pdu(function_code, ExceptionCode.SERVER_DEVICE_FAILURE)
        machine.processed()
        return reply

    async def _execute_broadcast(self, handler: Handler, request: Request | None) -> None:
        """Run a broadcast on every unit; units that share a store run it once."""
        done: set[int] = set()
        for unit, store in self.units.items():
            if id(store) in done:
                continue
            done.add(id(store))
            context = RequestContext(unit, store, broadcast=True)
            await _call(handler, request, context)


async def _call(
    handler: Handler, request: Request | None, context: RequestContext
) -> HandlerResult:
    result = handler(request, context)
    if inspect.isawaitable(result):
        awaited: HandlerResult = await result
        return awaited
    return result


def _exception_pdu(function_code: int, exception_code: int | None) -> bytes:
    # Raw bytes, not ExceptionPDU: a request with code 0 must still get its 01 answer.
    code = ExceptionCode.SERVER_DEVICE_FAILURE if exception_code is None else exception_code
    return bytes((function_code | EXCEPTION_BIT, code & 0xFF))


@asynccontextmanager
async def serve(
    port_or_url: str,
    units: Mapping[int, DataStore],
    *,
    baudrate: int = 19200,
    parity: str = "E",
    stopbits: float = 1,
    bytesize: int = 8,
    frame_gap: float | None = None,
    timing: TimingMode | str = TimingMode.TOLERANT,
    handlers: Mapping[int, Handler] | None = None,
    **options: Any,
) -> AsyncIterator[Slave]:
    """Open *port_or_url* and serve *units* on it for the duration of the ``async with``.

    *port_or_url* is a serial device path or ``rtu+tcp://host:port``; the line settings
    are the spec's 19200 8E1 by default; *options* go to
    :func:`aiortu.transport.open_stream` (``exclusive``, ``rs485``, ``local_echo``,
    ``connect_timeout``). Yields the running :class:`Slave`. Raises the transport's
    :class:`~aiortu.errors.PortError` subclasses when the port cannot be opened.
    """
    settings = LineSettings(baudrate, bytesize, parity, stopbits)
    stream = await open_stream(port_or_url, settings, **options)
    try:
        slave = Slave(
            stream, units, settings, frame_gap=frame_gap, timing=timing, handlers=handlers
        )
    except BaseException:
        await stream.aclose()
        raise
    async with slave:
        yield slave
