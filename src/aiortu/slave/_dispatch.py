"""The general route of a request, shared by every way of serving units.

`Dispatcher` holds what a server does with a request once it has one, whatever
carried it (a serial line, a TCP connection): the handlers by function code, the routes,
the hooks, and `Dispatcher._answer`, which takes a request through the state
machine's checks, the handler and the hooks to the reply PDU, with the spec's exception
codes. [`Slave`][aiortu.slave.Slave] (RTU on one line) and
[`ModbusTcpServer`][aiortu.slave.ModbusTcpServer] (Modbus TCP, many connections) are
both dispatchers; they differ only in how requests arrive and replies leave.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from aiortu._log import get_logger
from aiortu.core.codes import EXCEPTION_BIT, ExceptionCode
from aiortu.core.machines import SlaveMachine
from aiortu.core.model import AsyncDataStore, DataStore, Table
from aiortu.core.pdu import ExceptionPDU, Request, Response, decode_request, encode_exception
from aiortu.errors import ExceptionResponse, InvalidValue, MalformedPDU
from aiortu.slave._answer_at_once import AnswerAtOnce
from aiortu.slave._handlers import (
    Answer,
    Handler,
    HandlerResult,
    Reply,
    RequestContext,
)
from aiortu.slave._routes import RangeHandler, RoutedStore

__all__ = ("RESTART_COMMUNICATIONS", "AfterHook", "BeforeHook", "Dispatcher")

_log = get_logger(__name__)

BeforeHook = Callable[[Any, RequestContext], Answer]
"""Called before the handler with (request, context): `None` goes on to the handler, a
response or [`Reply`][aiortu.slave.Reply] answers instead of it, and raising
[`ExceptionResponse`][aiortu.errors.ExceptionResponse] refuses the request. May be async."""

AfterHook = Callable[[Any, RequestContext, HandlerResult], Answer]
"""Called after the handler with (request, context, its answer): `None` keeps the
answer, anything else replaces it. May be async. Not called when the handler raised."""

_FUNCTION_CODE_RANGE = range(1, EXCEPTION_BIT)

RESTART_COMMUNICATIONS = bytes((0x08, 0x00, 0x01))
"""Diagnostics, restart communications: the one request served in listen-only mode."""


class Dispatcher:
    """Units, their handlers, routes and hooks, and the general route of a request.

    A base class: a server sets it up with `_init_dispatch`, makes its shortcut
    (`_at_once`), builds the contexts with `_build_contexts`, and calls `_answer` for
    each request the machine let through.
    """

    units: dict[int, DataStore | AsyncDataStore]
    """The data store of each unit served."""
    machine: SlaveMachine
    """The state machine that decides what to answer."""
    _at_once: AnswerAtOnce
    """The server's shortcut, which answers a request at once where the general route would
    answer it the same (made by each server, on its carrier)."""

    def _init_dispatch(
        self,
        units: dict[int, DataStore | AsyncDataStore],
        machine: SlaveMachine,
        handlers: Mapping[int, Handler],
    ) -> None:
        self.units = units
        self.machine = machine
        self._before: list[BeforeHook] = []
        self._after: list[AfterHook] = []
        self._handlers: dict[int, Handler] = dict(handlers)
        self._routed: dict[int, RoutedStore] = {}
        self._contexts: dict[int, RequestContext] = {}
        self._broadcast_contexts: list[RequestContext] = []
        self._misbehaved: dict[int, object] = {}
        """Handlers and hooks logged for returning what is not an answer, by id (kept, so
        that no other object takes their id)."""

    def _configured(
        self,
        handlers: Mapping[int, Handler],
        stores: Mapping[int, DataStore | AsyncDataStore],
    ) -> None:
        """The handlers or the stores changed: the shortcut takes them."""
        self._at_once.configure(handlers, stores)

    # -- handlers --------------------------------------------------------------------

    def set_handler(self, function_code: int, handler: Handler | None) -> None:
        """Serve `function_code` with `handler`; `None` removes it (the code then gets 01).

        The handler is called as `handler(request, context)` with the decoded request
        (a [`RawPDU`][aiortu.core.pdu.RawPDU] for codes without a class) and a
        [`RequestContext`][aiortu.slave.RequestContext]; it returns the response PDU, or
        `None` to send nothing, and may be a coroutine function.
        """
        if function_code not in _FUNCTION_CODE_RANGE:
            raise InvalidValue("function_code", function_code, _FUNCTION_CODE_RANGE)
        if handler is None:
            self._handlers.pop(function_code, None)
        else:
            self._handlers[function_code] = handler
        self._configured(self._handlers, self._stores())

    def handler(self, function_code: int) -> Callable[[Handler], Handler]:
        """Decorator form of `set_handler`."""

        def register(handler: Handler) -> Handler:
            self.set_handler(function_code, handler)
            return handler

        return register

    def route(
        self,
        table: Table | str,
        addresses: range,
        handler: RangeHandler,
        *,
        units: Iterable[int] | None = None,
    ) -> None:
        """Serve `addresses` of `table` with `handler` on `units` (default: every unit).

        See [`aiortu.slave`][aiortu.slave]. A later route wins where routes overlap.
        """
        table = Table(table)
        for unit in self.units if units is None else units:
            if unit not in self.units:
                raise InvalidValue("unit", unit, sorted(self.units))
            routed = self._routed.get(unit)
            if routed is None:
                routed = self._routed[unit] = RoutedStore(self.units[unit], unit)
            routed.add(table, addresses, handler)
        self._build_contexts()

    def before_request(self, hook: BeforeHook) -> Callable[[], None]:
        """Call `hook` before each request's handler (see [`BeforeHook`][aiortu.slave.BeforeHook]).

        Returns a function that removes the hook.
        """
        self._before.append(hook)
        return lambda: self._before.remove(hook) if hook in self._before else None

    def after_request(self, hook: AfterHook) -> Callable[[], None]:
        """Call `hook` after each request's handler (see [`AfterHook`][aiortu.slave.AfterHook]).

        Returns a function that removes the hook.
        """
        self._after.append(hook)
        return lambda: self._after.remove(hook) if hook in self._after else None

    @property
    def function_codes(self) -> frozenset[int]:
        """The function codes this server serves."""
        return frozenset(self._handlers)

    def _stores(self) -> dict[int, DataStore | AsyncDataStore]:
        """The store of each unit, with its routes."""
        return {unit: self._routed.get(unit, store) for unit, store in self.units.items()}

    def _build_contexts(self) -> None:
        machine = self.machine
        stores = self._stores()
        self._contexts = {
            unit: RequestContext(unit, store, machine=machine) for unit, store in stores.items()
        }
        self._configured(self._handlers, stores)
        # A broadcast runs once per store: units that share one store run it once.
        seen: set[int] = set()
        self._broadcast_contexts = []
        for unit, store in stores.items():
            if id(self.units[unit]) not in seen:
                seen.add(id(self.units[unit]))
                self._broadcast_contexts.append(
                    RequestContext(unit, store, broadcast=True, machine=machine)
                )

    # -- the general route -----------------------------------------------------------

    async def _answer(self, unit: int, pdu: bytes) -> bytes | Reply | None:
        """Check and execute one request; return the reply PDU (or a Reply), or None."""
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
            code = machine.exception_code
            return encode_exception(
                function_code, ExceptionCode.SERVER_DEVICE_FAILURE if code is None else code
            )
        assert handler is not None
        failure: int = ExceptionCode.SERVER_DEVICE_FAILURE
        try:
            result = await self._execute(handler, request, unit)
            reply = _encoded(result)
        except ExceptionResponse as error:
            failure = error.code
        except _NotAnAnswer as error:
            self._log_not_an_answer(unit, function_code, error)
        except Exception:
            _log.exception("unit %d: the handler of function 0x%02X failed", unit, function_code)
        else:
            if isinstance(result, ExceptionPDU):
                machine.processing_failed(result.exception_code)
            else:
                machine.processed()
            return reply
        machine.processing_failed(failure)
        return encode_exception(function_code, failure)

    async def _execute(self, handler: Handler, request: Request | None, unit: int) -> HandlerResult:
        """Run `handler` for `unit`, or once per store for a broadcast (no answer then)."""
        if self.machine.broadcast:
            for context in self._broadcast_contexts:
                await self._run(handler, request, context)
            return None
        return await self._run(handler, request, self._contexts[unit])

    async def _run(
        self, handler: Handler, request: Request | None, context: RequestContext
    ) -> HandlerResult:
        """The handler's answer, with the hooks around it, each checked (see _checked)."""
        if not (self._before or self._after):
            return _checked(await _resolved(handler(request, context)), handler)
        for before in tuple(self._before):
            early = _checked(await _resolved(before(request, context)), before)
            if early is not None:
                return early
        result = _checked(await _resolved(handler(request, context)), handler)
        for after in tuple(self._after):
            replaced = _checked(await _resolved(after(request, context, result)), after)
            if replaced is not None:
                result = replaced
        return result

    def _log_not_an_answer(self, unit: int, function_code: int, error: _NotAnAnswer) -> None:
        """Log a handler or hook that returned what is not an answer, once for each."""
        source = error.source
        if id(source) in self._misbehaved:
            return
        self._misbehaved[id(source)] = source
        name = getattr(source, "__qualname__", type(source).__name__)
        _log.error(
            "unit %d, function 0x%02X: %s returned %s, not a response, an exception PDU, "
            "a Reply or None; answered with exception 04 (logged once for it)",
            unit,
            function_code,
            name,
            error.what,
        )


class _NotAnAnswer(Exception):
    """A handler or hook (`source`) returned something that is not an answer (`what`)."""

    def __init__(self, source: object, what: str) -> None:
        super().__init__(what)
        self.source = source
        self.what = what


async def _resolved(value: Any) -> Any:
    """`value`, awaited first if it is awaitable (handlers and hooks may be async)."""
    if inspect.isawaitable(value):
        return await value
    return value


def _checked(value: object, source: object) -> HandlerResult:
    """`value`, returned by `source`, if it is an answer: a Response, an ExceptionPDU,
    a valid Reply or None; else `_NotAnAnswer` (the request then gets 04)."""
    if value is None or isinstance(value, (Response, ExceptionPDU)):
        return value
    if isinstance(value, Reply):
        if _valid_reply(value):
            return value
        return _fail(source, "a Reply with a bad response, delay or unit")
    return _fail(source, _described(value))


def _described(value: object) -> str:
    """`value` as a log names it: `12345 (an int)` for a number, else its type (`a str`)."""
    name = type(value).__name__
    kind = f"{'an' if name[0] in 'aeiouAEIOU' else 'a'} {name}"
    if isinstance(value, int | float):
        return f"{value} ({kind})"
    return kind


def _encoded(result: HandlerResult) -> bytes | Reply | None:
    """What to send for `result`, a checked answer: the PDU's bytes, the Reply (its
    response encoded once here, so that a broken `encode` fails now, not after the
    delay), or None for nothing."""
    if result is None:
        return None
    if isinstance(result, Reply):
        if result.response is None:
            return None
        result.response.encode()
        return result
    return result.encode()


def _fail(source: object, what: str) -> HandlerResult:
    raise _NotAnAnswer(source, what)


def _valid_reply(reply: Reply) -> bool:
    response, delay, unit = reply.response, reply.delay, reply.unit
    return (
        (response is None or isinstance(response, (Response, ExceptionPDU)))
        and type(delay) in (int, float)
        and 0 <= delay < math.inf
        and (unit is None or (type(unit) is int and 0 <= unit <= 0xFF))
    )
