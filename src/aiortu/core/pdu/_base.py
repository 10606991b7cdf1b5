"""The base classes of every PDU, the exception and raw PDUs, and the packing helpers."""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import EXCEPTION_BIT, ExceptionCode
from aiortu.core.errors import InvalidRequest, InvalidValue, MalformedPDU

__all__ = (
    "ADDRESS_RANGE",
    "BYTE_RANGE",
    "MAX_PDU_LENGTH",
    "REGISTER_RANGE",
    "PDU",
    "ExceptionPDU",
    "RawPDU",
    "Request",
    "Response",
    "encode_exception",
    "pack_bits",
    "pack_registers",
    "unpack_bits",
    "unpack_registers",
)

MAX_PDU_LENGTH = 253
"""The longest PDU: a 256-byte RTU frame less the address byte and the CRC."""

ADDRESS_RANGE = range(0x10000)
"""Protocol addresses of every table: 0..65535."""

REGISTER_RANGE = range(0x10000)
"""Values of a 16-bit register: 0..65535."""

BYTE_RANGE = range(0x100)
"""Values of one byte."""


class PDU:
    """Base of every request, response and exception PDU."""

    __slots__ = ()

    function_code: ClassVar[int]
    """The function code this class encodes (for [`RawPDU`][aiortu.core.pdu.RawPDU], an instance
    field)."""

    _invalid: ClassVar[type[InvalidValue]] = InvalidValue

    def encode(self) -> bytes:
        """The PDU as bytes: the function code, then the data."""
        raise NotImplementedError

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        """Decode `pdu` (function code included) into this class.

        Raises [`MalformedPDU`][aiortu.errors.MalformedPDU] when the bytes break the spec.
        """
        raise NotImplementedError

    # Helpers shared by the subclasses. Building an object checks its fields with
    # ``_check``; decoding wraps the build in ``_decoding`` so that a field out of
    # range in received bytes becomes MalformedPDU, the peer's fault, not the caller's.

    def _check(self, field: str, value: int, allowed: range) -> None:
        # ``2.0 in range(3)`` and ``True in range(3)`` hold: the type is checked too.
        if type(value) is not int or value not in allowed:
            if isinstance(value, bool) or not isinstance(value, int):
                raise self._invalid(field, value, allowed, "an int is required")
            if value not in allowed:
                raise self._invalid(field, value, allowed)

    def _check_values(self, field: str, values: tuple[int, ...], allowed: range) -> None:
        if not values:
            return
        if allowed == REGISTER_RANGE:
            # Packing checks 0..65535 in C, about 2.5x faster than min() and max() on 125
            # values; on failure, min() and max() below find the culprit as before.
            try:
                struct.pack(f">{len(values)}H", *values)
            except struct.error:
                pass
            else:
                return
        low = min(values)
        high = max(values)
        if low < allowed.start or high >= allowed.stop:
            bad = low if low < allowed.start else high
            raise self._invalid(f"{field}[{values.index(bad)}]", bad, allowed)

    @classmethod
    def _build(cls, factory: Callable[[], Self]) -> Self:
        """Run `factory` (a constructor call on decoded fields), blaming the peer for errors.

        The MalformedPDU carries the exception a slave answers with: 02 when the field is
        an address range (its name starts with a word ending in `address`, such as
        `address + count` or `read_address + read_count`), else 03. Constructors check
        quantities before address ranges, so a request wrong in both gets 03, as the spec
        orders the checks.
        """
        try:
            return factory()
        except InvalidValue as error:
            raise MalformedPDU(
                f"{cls.__name__}: field out of range",
                field=error.field,
                value=error.value,
                allowed=error.allowed,
                exception_code=_exception_code_for(error.field),
            ) from None

    def _encode_words(self, *words: int) -> bytes:
        """The function code, then `words` as big-endian 16-bit fields (already checked)."""
        return bytes((self.function_code,)) + pack_registers(words)

    @classmethod
    def _decode_words(cls, pdu: bytes, count: int) -> Self:
        """Decode a PDU made of the function code and `count` 16-bit fields, in field order."""
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 1 + 2 * count)
        return cls._build(lambda: cls(*unpack_registers(pdu, 1, count)))

    @classmethod
    def _expect_function_code(cls, pdu: bytes) -> None:
        # decode_request dispatches on the code, but a class's decode may be called directly.
        if not pdu or pdu[0] != cls.function_code:
            raise MalformedPDU(
                f"{cls.__name__}: function code",
                field="function_code",
                value=pdu[0] if pdu else None,
                allowed=range(cls.function_code, cls.function_code + 1),
                exception_code=ExceptionCode.ILLEGAL_FUNCTION,
            )

    @classmethod
    def _expect_length(cls, pdu: bytes, length: int) -> None:
        if len(pdu) != length:
            raise MalformedPDU(
                f"{cls.__name__}: PDU length",
                field="length",
                value=len(pdu),
                allowed=range(length, length + 1),
            )

    @classmethod
    def _expect_min_length(cls, pdu: bytes, length: int) -> None:
        if len(pdu) < length:
            raise MalformedPDU(
                f"{cls.__name__}: PDU too short",
                field="length",
                value=len(pdu),
                allowed=range(length, MAX_PDU_LENGTH + 1),
            )


def _exception_code_for(field: str) -> ExceptionCode:
    if field.split(" ", 1)[0].endswith("address"):
        return ExceptionCode.ILLEGAL_DATA_ADDRESS
    return ExceptionCode.ILLEGAL_DATA_VALUE


class Request(PDU):
    """Base of the requests a master sends."""

    __slots__ = ()

    _invalid: ClassVar[type[InvalidValue]] = InvalidRequest

    response_class: ClassVar[type[Response]]
    """The class of the normal reply to this request."""

    broadcastable: ClassVar[bool] = False
    """Whether the spec lets this request go to unit 0 (only writes may)."""

    def check_response(self, response: Response) -> None:
        """Raise [`MalformedPDU`][aiortu.errors.MalformedPDU] if `response` cannot answer this
        request.

        The base checks the class; subclasses check what the reply echoes or counts.
        """
        if type(response) is not self.response_class:
            raise MalformedPDU(
                f"{type(response).__name__} does not answer {type(self).__name__}",
                exception_code=ExceptionCode.ILLEGAL_FUNCTION,
            )

    def _check_echo(self, field: str, received: int, sent: int) -> None:
        """Raise MalformedPDU unless the reply's `field` repeats what the request sent."""
        if received != sent:
            raise MalformedPDU(
                f"reply to {type(self).__name__} does not echo the request",
                field=field,
                value=received,
                allowed=range(sent, sent + 1),
            )


class Response(PDU):
    """Base of the normal (not exception) replies a slave sends."""

    __slots__ = ()


@dataclass(frozen=True, slots=True)
class ExceptionPDU(PDU):
    """An exception response: the request's function code with the top bit set, and a code.

    `function_code` here is the request's function code (without the top bit);
    `exception_code` is an [`ExceptionCode`][aiortu.core.codes.ExceptionCode] when the spec
    defines it, else the raw number.
    """

    function_code: int  # type: ignore[misc]  # an instance field here, a ClassVar elsewhere
    exception_code: int

    def __post_init__(self) -> None:
        self._check("function_code", self.function_code, range(1, EXCEPTION_BIT))
        self._check("exception_code", self.exception_code, BYTE_RANGE)
        with contextlib.suppress(ValueError):
            object.__setattr__(self, "exception_code", ExceptionCode(self.exception_code))

    def encode(self) -> bytes:
        return encode_exception(self.function_code, self.exception_code)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_length(pdu, 2)
        if not pdu[0] & EXCEPTION_BIT:
            raise MalformedPDU(
                "not an exception response",
                field="function_code",
                value=pdu[0],
                allowed="0x81..0xFF",
            )
        return cls._build(lambda: cls(pdu[0] & 0x7F, pdu[1]))


def encode_exception(function_code: int, exception_code: int) -> bytes:
    """The exception response PDU to a request of `function_code` with `exception_code`: the
    bytes [`ExceptionPDU.encode`][aiortu.core.pdu.ExceptionPDU.encode] writes, for any code a
    request may carry (code 0 or a reply's own code included, which gets 01 from a server)."""
    return bytes(((function_code | EXCEPTION_BIT) & 0xFF, exception_code & 0xFF))


@dataclass(frozen=True, slots=True)
class RawPDU(Request, Response):
    """A PDU of a function code aiortu has no class for: user-defined and vendor codes.

    `data` is everything after the function code. Used as a request and as a response.
    """

    function_code: int  # type: ignore[misc]
    data: bytes = b""

    def __post_init__(self) -> None:
        self._check("function_code", self.function_code, range(1, EXCEPTION_BIT))
        object.__setattr__(self, "data", bytes(self.data))
        self._check("len(data)", len(self.data), range(MAX_PDU_LENGTH))

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + self.data

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_min_length(pdu, 1)
        return cls._build(lambda: cls(pdu[0], bytes(pdu[1:])))

    def check_response(self, response: Response) -> None:
        if not isinstance(response, RawPDU) or response.function_code != self.function_code:
            raise MalformedPDU("reply function code differs from the request's")


RawPDU.response_class = RawPDU


def pack_registers(values: Iterable[int]) -> bytes:
    """Big-endian 16-bit words (the values must already be checked)."""
    values = tuple(values)
    return struct.pack(f">{len(values)}H", *values)


def unpack_registers(data: bytes, offset: int, count: int) -> tuple[int, ...]:
    """`count` big-endian 16-bit words from `data` at `offset` (the length must be checked)."""
    return struct.unpack_from(f">{count}H", data, offset)


def pack_bits(bits: Iterable[bool]) -> bytes:
    """Bits packed LSB first, the last byte padded with zeros."""
    out = bytearray()
    byte = 0
    position = 0
    for bit in bits:
        if bit:
            byte |= 1 << position
        position += 1
        if position == 8:
            out.append(byte)
            byte = 0
            position = 0
    if position:
        out.append(byte)
    return bytes(out)


def unpack_bits(data: bytes) -> tuple[bool, ...]:
    """Every bit of `data`, LSB first: 8 bits per byte, padding included."""
    return tuple(_BYTE_BITS[byte][index] for byte in data for index in range(8))


_BYTE_BITS: tuple[tuple[bool, ...], ...] = tuple(
    tuple(bool(byte >> index & 1) for index in range(8)) for byte in range(256)
)
