"""One client request on the line: raw PDU in, raw PDU out, failures as gateway exceptions.

A request PDU of a function code aiortu knows is sent as that code's class, so the engine checks
the reply against it (byte count, echoed address and values) before it is returned. A PDU aiortu
has no class for (a user-defined code), or one that does not decode (a quantity outside the
spec's range: the device, not the gateway, says what it makes of it), goes out as it came, and
any reply with its function code (or the exception form) answers it. Frames go out bit for bit:
a request whose class would encode it differently (FC 0F with padding bits set) goes out as it
came, its reply checked on its function code only.

Two requests get no reply by the spec: diagnostics 08/04 (force listen-only mode), and 08/01
(restart communications) to a unit in listen-only mode. They are sent without a wait for a
reply (then the turnaround delay) and answered with the echo of the request, the reply a
listening device gives to diagnostics (see `forward_unanswered`).
"""

from __future__ import annotations

from collections.abc import Awaitable
from dataclasses import dataclass
from typing import ClassVar

from aiortu._log import get_logger
from aiortu.core.codes import (
    BROADCAST_UNIT,
    DiagnosticSubFunction,
    ExceptionCode,
    FunctionCode,
)
from aiortu.core.machines import RetryPolicy, Transaction
from aiortu.core.pdu import (
    ExceptionPDU,
    RawPDU,
    Request,
    Response,
    decode_request,
    encode_exception,
)
from aiortu.errors import ConnectionLost, MalformedPDU, ModbusError
from aiortu.master import Master

__all__ = (
    "COALESCED_CODES",
    "FORCE_LISTEN_ONLY",
    "RESTART",
    "exception_reply",
    "forward",
    "forward_broadcast",
    "forward_unanswered",
    "on_the_line",
    "reply_from",
    "reply_pdu",
    "request_of",
    "start_forward",
)

_log = get_logger(__name__)

COALESCED_CODES = frozenset(
    {
        FunctionCode.READ_COILS,
        FunctionCode.READ_DISCRETE_INPUTS,
        FunctionCode.READ_HOLDING_REGISTERS,
        FunctionCode.READ_INPUT_REGISTERS,
    }
)
"""The reads that identical requests in flight at once share: they change nothing."""

_NO_RESPONSE = ExceptionCode.GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND
_NO_PATH = ExceptionCode.GATEWAY_PATH_UNAVAILABLE


@dataclass(frozen=True, slots=True)
class _AsReceived(RawPDU):
    """A request forwarded byte for byte; a reply with its function code answers it."""

    def check_response(self, response: Response) -> None:
        if response.function_code != self.function_code:
            raise MalformedPDU("reply function code differs from the request's")


@dataclass(frozen=True, slots=True)
class _CoilsAsReceived(_AsReceived):
    """An FC 0F write with padding bits set, forwarded as it came: still a write to broadcast."""

    broadcastable: ClassVar[bool] = True


_PADDED = FunctionCode.WRITE_MULTIPLE_COILS  # the one code whose encoding has free bits
_DIAGNOSTICS = FunctionCode.DIAGNOSTICS
FORCE_LISTEN_ONLY = bytes((_DIAGNOSTICS, 0x00, DiagnosticSubFunction.FORCE_LISTEN_ONLY_MODE))
"""The first bytes of a diagnostics 08/04 request (force listen-only mode)."""
RESTART = bytes((_DIAGNOSTICS, 0x00, DiagnosticSubFunction.RESTART_COMMUNICATIONS))
"""The first bytes of a diagnostics 08/01 request (restart communications)."""


def exception_reply(pdu: bytes, code: ExceptionCode) -> bytes:
    """The exception reply PDU to request `pdu` with `code`."""
    return encode_exception(pdu[0], code)


def request_of(pdu: bytes) -> Request:
    """The request to send for the client's `pdu` (see the module docstring)."""
    try:
        request = decode_request(pdu)
    except MalformedPDU:
        return _AsReceived(pdu[0], pdu[1:])
    if pdu[0] == _PADDED and request.encode() != pdu:
        return _CoilsAsReceived(pdu[0], pdu[1:])
    return request


async def forward(master: Master, unit: int, pdu: bytes, priority: int, order: int) -> bytes:
    """The reply PDU to `pdu` from `unit` (1..247): the device's, or exception 0B when it did not
    answer (after the master's retries, or at once while it is offline and the master fails fast),
    0A while the line is down. Queued by `priority`, then `order` (see `on_the_line`)."""
    if pdu[0] == 0 or pdu[0] & 0x80:
        # Function code 0, or an exception's: not a request, nothing on the line answers it.
        return exception_reply(pdu, ExceptionCode.ILLEGAL_FUNCTION)
    awaitable = start_forward(master, unit, request_of(pdu), priority, order)
    return await reply_from(awaitable, unit, pdu)


def start_forward(
    master: Master, unit: int, request: Request, priority: int, order: int
) -> Awaitable[Response | ExceptionPDU | None]:
    """Hand `request` (made by `request_of`, or kept as its bytes: `_as_bytes.py`) to `unit`
    on the line of `master`; return the awaitable of its reply (see `on_the_line`), which
    `reply_pdu` turns into the reply PDU."""
    policy = master.policy.for_function(request.function_code)
    return on_the_line(master, Transaction(unit, request, master.timeout, policy), priority, order)


async def reply_from(
    awaitable: Awaitable[Response | ExceptionPDU | None], unit: int, pdu: bytes
) -> bytes:
    """The reply PDU to `pdu` once `awaitable` (from `start_forward`) is done."""
    try:
        reply = await awaitable
    except ModbusError as error:
        return reply_pdu(pdu, unit, None, error)
    return reply_pdu(pdu, unit, reply, None)


def reply_pdu(
    pdu: bytes, unit: int, reply: Response | ExceptionPDU | None, error: BaseException | None
) -> bytes:
    """The reply PDU to request `pdu` forwarded to `unit`: `reply` encoded, or for `error` (a
    [`ModbusError`][aiortu.errors.ModbusError]) exception 0A (the line is down) or 0B (no answer).
    Any other error is re-raised: a bug."""
    if error is None:
        assert reply is not None
        return reply.encode()
    if isinstance(error, ConnectionLost):
        _log.debug("gateway: unit %d: the line is down (%s)", unit, error)
        return exception_reply(pdu, _NO_PATH)
    if isinstance(error, ModbusError):
        _log.debug("gateway: unit %d did not answer: %s", unit, error)
        return exception_reply(pdu, _NO_RESPONSE)
    raise error


async def forward_broadcast(master: Master, pdu: bytes, priority: int, order: int) -> bool:
    """Send `pdu` to every unit and wait the turnaround delay; False when it was not sent (a
    request the spec does not let be broadcast, or the line is down)."""
    request = request_of(pdu)
    if not request.broadcastable:
        _log.debug("gateway: function code %d may not be broadcast; not sent", pdu[0])
        return False
    transaction = Transaction(
        BROADCAST_UNIT,
        request,
        master.timeout,
        RetryPolicy(0),
        expects_reply=False,
        turnaround=master.turnaround_delay,
    )
    try:
        await on_the_line(master, transaction, priority, order)
    except ModbusError as error:
        _log.debug("gateway: broadcast of function code %d not sent: %s", pdu[0], error)
        return False
    return True


async def forward_unanswered(
    master: Master, unit: int, pdu: bytes, priority: int, order: int
) -> bytes:
    """Send `pdu` (08/04, or 08/01 to a unit in listen-only mode) to `unit` without a wait for a
    reply, and return the echo of the request (0A when the line is down): the spec says the
    device never answers it, so a wait would cost the timeout and the client's next exchange.
    Sent even while the unit is offline: it is how a unit silenced by 08/04 comes back."""
    transaction = Transaction(
        unit,
        request_of(pdu),
        master.timeout,
        RetryPolicy(0),
        expects_reply=False,
        turnaround=master.turnaround_delay,
    )
    try:
        await on_the_line(master, transaction, priority, order)
    except ModbusError as error:
        _log.debug("gateway: unit %d: diagnostics not sent: %s", unit, error)
        return exception_reply(pdu, _NO_PATH)
    return pdu


def on_the_line(
    master: Master, transaction: Transaction, priority: int, order: int
) -> Awaitable[Response | ExceptionPDU | None]:
    """Run `transaction` on the line of `master`: the gateway's one call into the engine.

    Queued transactions go by the listener's `priority`, then by `order`, the connection's
    turn (see [`Gateway`][aiortu.gateway.Gateway]: fairness between connections is this key).
    A caller cancelled while queued is dropped from the queue; one whose request is on the wire
    leaves it to complete, without retries. (A plain function: one coroutine frame less on
    every resumption of the transaction.)"""
    transaction.priority = priority
    transaction.order = order
    return master.seam.submit(transaction)
