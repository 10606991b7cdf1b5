"""The PDUs of the serial-line-only functions: read exception status (07), diagnostics (08),
get comm event counter (0B), get comm event log (0C) and report server ID (11).

These functions read the state of a device's serial interface rather than its data tables, so their
replies carry status words, counters and device-specific bytes. Diagnostics carries a sub-function;
the spec fixes the data of the sub-functions it defines (see
[`DiagnosticsRequest`][aiortu.core.pdu.DiagnosticsRequest]), and any other sub-function
travels with its data unchecked so that vendor extensions still round trip.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import DiagnosticSubFunction, FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu._base import (
    BYTE_RANGE,
    MAX_PDU_LENGTH,
    PDU,
    REGISTER_RANGE,
    Request,
    Response,
)

__all__ = (
    "COMM_EVENT_STATUS_BUSY",
    "COMM_EVENT_STATUS_READY",
    "MAX_COMM_EVENTS",
    "MAX_DIAGNOSTIC_DATA",
    "DiagnosticsRequest",
    "DiagnosticsResponse",
    "GetCommEventCounterRequest",
    "GetCommEventCounterResponse",
    "GetCommEventLogRequest",
    "GetCommEventLogResponse",
    "ReadExceptionStatusRequest",
    "ReadExceptionStatusResponse",
    "ReportServerIdRequest",
    "ReportServerIdResponse",
)

MAX_DIAGNOSTIC_DATA = MAX_PDU_LENGTH - 3
"""The most data bytes a diagnostics PDU can carry after its code and sub-function (250)."""

MAX_COMM_EVENTS = 64
"""The most event bytes a comm event log reply holds."""

COMM_EVENT_STATUS_READY = 0x0000
"""Comm event status word: no program command is still being processed."""

COMM_EVENT_STATUS_BUSY = 0xFFFF
"""Comm event status word: a previous program command is still being processed."""

_SUB_FUNCTION_RANGE = range(0x10000)
_DIAGNOSTIC_DATA_LENGTH = range(MAX_DIAGNOSTIC_DATA + 1)
_EVEN_DIAGNOSTIC_DATA_LENGTH = range(0, MAX_DIAGNOSTIC_DATA + 1, 2)
_ONE_WORD = range(2, 3)
_ZERO_WORD = range(1)
_RESTART_VALUES = (0x0000, 0xFF00)
_EVENTS_LENGTH = range(MAX_COMM_EVENTS + 1)
_EVENT_LOG_BYTE_COUNT = range(6, 6 + MAX_COMM_EVENTS + 1)
_SERVER_ID_BYTE_COUNT = range(2, MAX_PDU_LENGTH - 1)
_RUN_OFF = 0x00
_RUN_ON = 0xFF

# Sub-functions whose request data must be 0x0000 and whose reply holds one 16-bit value
# (a register or a counter; for the two "clear" sub-functions, the echoed 0x0000).
_READ_WORD_SUB_FUNCTIONS = frozenset(
    {
        DiagnosticSubFunction.RETURN_DIAGNOSTIC_REGISTER,
        DiagnosticSubFunction.CLEAR_COUNTERS_AND_DIAGNOSTIC_REGISTER,
        DiagnosticSubFunction.RETURN_BUS_MESSAGE_COUNT,
        DiagnosticSubFunction.RETURN_BUS_COMMUNICATION_ERROR_COUNT,
        DiagnosticSubFunction.RETURN_BUS_EXCEPTION_ERROR_COUNT,
        DiagnosticSubFunction.RETURN_SERVER_MESSAGE_COUNT,
        DiagnosticSubFunction.RETURN_SERVER_NO_RESPONSE_COUNT,
        DiagnosticSubFunction.RETURN_SERVER_NAK_COUNT,
        DiagnosticSubFunction.RETURN_SERVER_BUSY_COUNT,
        DiagnosticSubFunction.RETURN_BUS_CHARACTER_OVERRUN_COUNT,
        DiagnosticSubFunction.CLEAR_OVERRUN_COUNTER_AND_FLAG,
    }
)

# Sub-functions whose reply must repeat the request's data byte for byte.
_ECHO_SUB_FUNCTIONS = frozenset(
    {
        DiagnosticSubFunction.RETURN_QUERY_DATA,
        DiagnosticSubFunction.RESTART_COMMUNICATIONS,
        DiagnosticSubFunction.CHANGE_ASCII_INPUT_DELIMITER,
    }
)


class _NoFieldsRequest(Request):
    """Requests made of the function code alone (07, 0B, 0C, 11)."""

    __slots__ = ()

    def encode(self) -> bytes:
        return bytes((self.function_code,))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 1)
        return cls()


# ---------------------------------------------------------------------------------------
# 07 Read Exception Status


@dataclass(frozen=True, slots=True)
class ReadExceptionStatusResponse(Response):
    """Reply to read exception status: eight device-defined status bits in one byte.

    The meaning of each bit is up to the device;
    [`bits`][aiortu.core.pdu.ReadExceptionStatusResponse.bits] lists them LSB first.
    """

    function_code: ClassVar[int] = FunctionCode.READ_EXCEPTION_STATUS
    status: int

    def __post_init__(self) -> None:
        self._check("status", self.status, BYTE_RANGE)

    @property
    def bits(self) -> tuple[bool, ...]:
        """The eight status bits, bit 0 first."""
        return tuple(bool(self.status >> index & 1) for index in range(8))

    def encode(self) -> bytes:
        return bytes((self.function_code, self.status))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 2)
        return cls._build(lambda: cls(pdu[1]))


@dataclass(frozen=True, slots=True)
class ReadExceptionStatusRequest(_NoFieldsRequest):
    """Read the eight exception status bits of a device (serial line only; no fields)."""

    function_code: ClassVar[int] = FunctionCode.READ_EXCEPTION_STATUS
    response_class: ClassVar[type[Response]] = ReadExceptionStatusResponse


# ---------------------------------------------------------------------------------------
# 08 Diagnostics


def _as_bytes(owner: PDU, name: str, value: object) -> bytes:
    # Not bytes(value): bytes(n) would silently make n zero bytes of an int meant as a word.
    if not isinstance(value, bytes | bytearray | memoryview):
        raise TypeError(f"{type(owner).__name__}.{name} must be bytes, not {type(value).__name__}")
    return bytes(value)


def _check_diagnostic(pdu: PDU, sub_function: int, data: bytes, *, reply: bool) -> None:
    """Check `data` against what the spec fixes for `sub_function` (request or reply)."""
    if sub_function == DiagnosticSubFunction.RETURN_QUERY_DATA:
        pdu._check("len(data)", len(data), _EVEN_DIAGNOSTIC_DATA_LENGTH)
        return
    if not isinstance(sub_function, DiagnosticSubFunction):
        pdu._check("len(data)", len(data), _DIAGNOSTIC_DATA_LENGTH)
        return
    pdu._check("len(data)", len(data), _ONE_WORD)
    word = int.from_bytes(data, "big")
    if sub_function == DiagnosticSubFunction.RESTART_COMMUNICATIONS:
        if word not in _RESTART_VALUES:
            raise pdu._invalid("data", word, "0x0000 or 0xFF00 (clear the event log)")
    elif sub_function == DiagnosticSubFunction.CHANGE_ASCII_INPUT_DELIMITER:
        if word & 0xFF:
            raise pdu._invalid("data", word, "(char << 8) | 0x00: the low byte must be 0")
    elif sub_function == DiagnosticSubFunction.FORCE_LISTEN_ONLY_MODE or not reply:
        pdu._check("data", word, _ZERO_WORD)


@dataclass(frozen=True, slots=True)
class DiagnosticsResponse(Response):
    """Reply to diagnostics: the sub-function echoed and its data.

    For the counters and the diagnostic register (02, 0A..12, 14) the data is one 16-bit value
    ([`value`][aiortu.core.pdu.DiagnosticsResponse.value]); for return query data (00)
    it echoes the request's even-length data; for 01 and 03 it echoes the request's word. A reply to
    force listen-only mode (04) never comes on the wire but may be built, with data 0x0000.
    Sub-functions the spec does not define for a serial line keep up to 250 data bytes unchecked.
    """

    function_code: ClassVar[int] = FunctionCode.DIAGNOSTICS
    sub_function: int
    data: bytes

    def __post_init__(self) -> None:
        self._check("sub_function", self.sub_function, _SUB_FUNCTION_RANGE)
        object.__setattr__(self, "sub_function", _known_sub_function(self.sub_function))
        object.__setattr__(self, "data", _as_bytes(self, "data", self.data))
        _check_diagnostic(self, self.sub_function, self.data, reply=True)

    @property
    def value(self) -> int:
        """The data as one big-endian number (a counter or register for 02, 0A..14)."""
        return int.from_bytes(self.data, "big")

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + self.sub_function.to_bytes(2, "big") + self.data

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 3)
        return cls._build(lambda: cls(int.from_bytes(pdu[1:3], "big"), bytes(pdu[3:])))


def _known_sub_function(value: int) -> int:
    try:
        return DiagnosticSubFunction(value)
    except ValueError:
        return value


@dataclass(frozen=True, slots=True)
class DiagnosticsRequest(Request):
    """Run diagnostics sub-function `sub_function` (0..65535) with `data` (serial line only).

    `sub_function` becomes a [`DiagnosticSubFunction`][aiortu.core.codes.DiagnosticSubFunction] when
    the spec defines it, else stays a raw number. The data is checked where the spec fixes it:

    - 00 return query data: any even number of bytes (0..250), echoed by the reply;
    - 01 restart communications: 0x0000, or 0xFF00 to also clear the event log;
    - 02, 04, 0A..12, 14: 0x0000 (the default);
    - 03 change ASCII input delimiter: the character in the high byte, 0x00 in the low one.

    Other sub-functions carry 0..250 bytes unchecked. Force listen-only mode (04) gets no
    reply; the caller must not wait for one.
    """

    function_code: ClassVar[int] = FunctionCode.DIAGNOSTICS
    response_class: ClassVar[type[Response]] = DiagnosticsResponse
    sub_function: int
    data: bytes = b"\x00\x00"

    def __post_init__(self) -> None:
        self._check("sub_function", self.sub_function, _SUB_FUNCTION_RANGE)
        object.__setattr__(self, "sub_function", _known_sub_function(self.sub_function))
        object.__setattr__(self, "data", _as_bytes(self, "data", self.data))
        _check_diagnostic(self, self.sub_function, self.data, reply=False)

    @property
    def expects_reply(self) -> bool:
        """False for force listen-only mode (04), which the device never answers."""
        return self.sub_function != DiagnosticSubFunction.FORCE_LISTEN_ONLY_MODE

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + self.sub_function.to_bytes(2, "big") + self.data

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 3)
        return cls._build(lambda: cls(int.from_bytes(pdu[1:3], "big"), bytes(pdu[3:])))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, DiagnosticsResponse)
        if response.sub_function != self.sub_function:
            raise MalformedPDU(
                "reply sub-function differs from the request's",
                field="sub_function",
                value=response.sub_function,
                allowed=range(self.sub_function, self.sub_function + 1),
            )
        if self.sub_function in _ECHO_SUB_FUNCTIONS and response.data != self.data:
            raise MalformedPDU(
                "reply data does not echo the request's",
                field="data",
                value=response.data,
                allowed=self.data,
            )


# ---------------------------------------------------------------------------------------
# 0B Get Comm Event Counter


def _check_status(pdu: PDU, status: int) -> None:
    if status not in (COMM_EVENT_STATUS_READY, COMM_EVENT_STATUS_BUSY):
        raise pdu._invalid("status", status, "0x0000 (ready) or 0xFFFF (busy)")


@dataclass(frozen=True, slots=True)
class GetCommEventCounterResponse(Response):
    """Reply to get comm event counter: the status word (0x0000 or 0xFFFF) and the count.

    The count (0..65535) is the number of messages the device completed successfully.
    """

    function_code: ClassVar[int] = FunctionCode.GET_COMM_EVENT_COUNTER
    status: int
    event_count: int

    def __post_init__(self) -> None:
        _check_status(self, self.status)
        self._check("event_count", self.event_count, REGISTER_RANGE)

    @property
    def busy(self) -> bool:
        """Whether the device was still processing a previous program command."""
        return self.status == COMM_EVENT_STATUS_BUSY

    def encode(self) -> bytes:
        return (
            bytes((self.function_code,))
            + self.status.to_bytes(2, "big")
            + self.event_count.to_bytes(2, "big")
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)


@dataclass(frozen=True, slots=True)
class GetCommEventCounterRequest(_NoFieldsRequest):
    """Read the comm event counter of a device (serial line only; no fields)."""

    function_code: ClassVar[int] = FunctionCode.GET_COMM_EVENT_COUNTER
    response_class: ClassVar[type[Response]] = GetCommEventCounterResponse


# ---------------------------------------------------------------------------------------
# 0C Get Comm Event Log


@dataclass(frozen=True, slots=True)
class GetCommEventLogResponse(Response):
    """Reply to get comm event log: status, event count, message count and 0..64 events.

    `events` holds one byte per event, the most recent first, as the device sent them; the
    byte count on the wire is 6 + `len(events)`.
    """

    function_code: ClassVar[int] = FunctionCode.GET_COMM_EVENT_LOG
    status: int
    event_count: int
    message_count: int
    events: bytes = b""

    def __post_init__(self) -> None:
        _check_status(self, self.status)
        self._check("event_count", self.event_count, REGISTER_RANGE)
        self._check("message_count", self.message_count, REGISTER_RANGE)
        object.__setattr__(self, "events", _as_bytes(self, "events", self.events))
        self._check("len(events)", len(self.events), _EVENTS_LENGTH)

    @property
    def busy(self) -> bool:
        """Whether the device was still processing a previous program command."""
        return self.status == COMM_EVENT_STATUS_BUSY

    def encode(self) -> bytes:
        return (
            bytes((self.function_code, 6 + len(self.events)))
            + self.status.to_bytes(2, "big")
            + self.event_count.to_bytes(2, "big")
            + self.message_count.to_bytes(2, "big")
            + self.events
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 8)
        byte_count = pdu[1]
        if byte_count not in _EVENT_LOG_BYTE_COUNT:
            raise MalformedPDU(
                cls.__name__, field="byte_count", value=byte_count, allowed=_EVENT_LOG_BYTE_COUNT
            )
        cls._expect_length(pdu, 2 + byte_count)
        return cls._build(
            lambda: cls(
                int.from_bytes(pdu[2:4], "big"),
                int.from_bytes(pdu[4:6], "big"),
                int.from_bytes(pdu[6:8], "big"),
                bytes(pdu[8:]),
            )
        )


@dataclass(frozen=True, slots=True)
class GetCommEventLogRequest(_NoFieldsRequest):
    """Read the comm event log of a device (serial line only; no fields)."""

    function_code: ClassVar[int] = FunctionCode.GET_COMM_EVENT_LOG
    response_class: ClassVar[type[Response]] = GetCommEventLogResponse


# ---------------------------------------------------------------------------------------
# 11 Report Server ID


@dataclass(frozen=True, slots=True)
class ReportServerIdResponse(Response):
    """Reply to report server ID: the server id, the run indicator, then additional data.

    The spec leaves the length of the id to each device, and the wire carries only the total byte
    count, so decoding needs a rule: the id is the first byte plus every following byte up to the
    first 0x00 or 0xFF, that byte is the run indicator (0x00 off, 0xFF on), and the rest is
    additional data. For the common one-byte id this is exact. An id longer than one byte that holds
    a 0x00 or 0xFF after its first byte decodes split at the wrong place, but nothing is lost:
    encoding the decoded object gives the same bytes back. When a device documents its id length,
    [`with_id_length`][aiortu.core.pdu.ReportServerIdResponse.with_id_length] re-splits
    a decoded reply. Limits: `server_id` at least 1 byte, and the whole PDU 253 bytes (id +
    additional data at most 250).
    """

    function_code: ClassVar[int] = FunctionCode.REPORT_SERVER_ID
    server_id: bytes
    run_indicator: bool
    additional_data: bytes = b""

    def __post_init__(self) -> None:
        object.__setattr__(self, "server_id", _as_bytes(self, "server_id", self.server_id))
        object.__setattr__(self, "run_indicator", bool(self.run_indicator))
        object.__setattr__(
            self, "additional_data", _as_bytes(self, "additional_data", self.additional_data)
        )
        self._check("len(server_id)", len(self.server_id), range(1, _SERVER_ID_BYTE_COUNT.stop))
        self._check(
            "len(server_id) + 1 + len(additional_data)",
            len(self.server_id) + 1 + len(self.additional_data),
            _SERVER_ID_BYTE_COUNT,
        )

    def _payload(self) -> bytes:
        run = _RUN_ON if self.run_indicator else _RUN_OFF
        return self.server_id + bytes((run,)) + self.additional_data

    def encode(self) -> bytes:
        payload = self._payload()
        return bytes((self.function_code, len(payload))) + payload

    def with_id_length(self, id_length: int) -> Self:
        """The same bytes split with a server id of `id_length` bytes (as a device documents).

        Raises [`InvalidValue`][aiortu.errors.InvalidValue] when the byte after the id is not a run
        indicator (0x00 or 0xFF) or `id_length` does not fit.
        """
        payload = self._payload()
        self._check("id_length", id_length, range(1, len(payload)))
        run = payload[id_length]
        if run not in (_RUN_OFF, _RUN_ON):
            raise self._invalid(f"byte {id_length} (run indicator)", run, "0x00 or 0xFF")
        return type(self)(payload[:id_length], run == _RUN_ON, payload[id_length + 1 :])

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 4)
        byte_count = pdu[1]
        if byte_count not in _SERVER_ID_BYTE_COUNT:
            raise MalformedPDU(
                cls.__name__, field="byte_count", value=byte_count, allowed=_SERVER_ID_BYTE_COUNT
            )
        cls._expect_length(pdu, 2 + byte_count)
        payload = bytes(pdu[2:])
        for position in range(1, len(payload)):
            if payload[position] in (_RUN_OFF, _RUN_ON):
                break
        else:
            raise MalformedPDU(
                f"{cls.__name__}: no run indicator (0x00 or 0xFF) after the server id",
                field="run_indicator",
                value=payload[1:],
                allowed="a 0x00 or 0xFF byte after the first byte",
            )
        run = payload[position] == _RUN_ON
        return cls._build(lambda: cls(payload[:position], run, payload[position + 1 :]))


@dataclass(frozen=True, slots=True)
class ReportServerIdRequest(_NoFieldsRequest):
    """Ask a device for its server id, run indicator and device-specific data (no fields)."""

    function_code: ClassVar[int] = FunctionCode.REPORT_SERVER_ID
    response_class: ClassVar[type[Response]] = ReportServerIdResponse
