"""The PDUs of the bit tables: read coils (01), read discrete inputs (02), and the coil writes
(05, 0F).

Bits travel packed eight to a byte, the first bit in the least significant position, the last byte
padded with zeros. A decoded read response therefore holds every bit of its bytes, padding included;
[`ReadCoilsRequest.bits_of`][aiortu.core.pdu.ReadCoilsRequest.bits_of] trims them to the count
asked.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import ExceptionCode, FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu._base import (
    ADDRESS_RANGE,
    Request,
    Response,
    pack_bits,
    pack_registers,
    unpack_bits,
    unpack_registers,
)

__all__ = (
    "MAX_READ_BITS",
    "MAX_WRITE_BITS",
    "ReadCoilsRequest",
    "ReadCoilsResponse",
    "ReadDiscreteInputsRequest",
    "ReadDiscreteInputsResponse",
    "WriteMultipleCoilsRequest",
    "WriteMultipleCoilsResponse",
    "WriteSingleCoilRequest",
    "WriteSingleCoilResponse",
)

MAX_READ_BITS = 2000
"""The most coils or discrete inputs one read may ask for (0x7D0)."""

MAX_WRITE_BITS = 1968
"""The most coils one write multiple coils (0F) may set (0x7B0)."""

_READ_BITS_COUNT = range(1, MAX_READ_BITS + 1)
_READ_BITS_BYTE_COUNT = range(1, (MAX_READ_BITS + 7) // 8 + 1)
_WRITE_BITS_COUNT = range(1, MAX_WRITE_BITS + 1)
_END_RANGE = range(ADDRESS_RANGE.stop + 1)

_COIL_ON = 0xFF00
_COIL_OFF = 0x0000


@dataclass(frozen=True, slots=True)
class ReadCoilsResponse(Response):
    """Reply to read coils: the bits, LSB first, padded to whole bytes when decoded."""

    function_code: ClassVar[int] = FunctionCode.READ_COILS
    values: tuple[bool, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", tuple(bool(value) for value in self.values))
        self._check("len(values)", len(self.values), range(1, _READ_BITS_BYTE_COUNT.stop * 8 - 7))

    def encode(self) -> bytes:
        packed = pack_bits(self.values)
        return bytes((self.function_code, len(packed))) + packed

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 3)
        byte_count = pdu[1]
        if byte_count not in _READ_BITS_BYTE_COUNT:
            raise MalformedPDU(
                cls.__name__, field="byte_count", value=byte_count, allowed=_READ_BITS_BYTE_COUNT
            )
        cls._expect_length(pdu, 2 + byte_count)
        return cls._build(lambda: cls(unpack_bits(pdu[2:])))


@dataclass(frozen=True, slots=True)
class ReadCoilsRequest(Request):
    """Read `count` (1..2000) coils from protocol address `address`."""

    function_code: ClassVar[int] = FunctionCode.READ_COILS
    response_class: ClassVar[type[Response]] = ReadCoilsResponse
    address: int
    count: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("count", self.count, _READ_BITS_COUNT)
        self._check("address + count", self.address + self.count, range(ADDRESS_RANGE.stop + 1))

    def encode(self) -> bytes:
        return (
            bytes((self.function_code,))
            + self.address.to_bytes(2, "big")
            + self.count.to_bytes(2, "big")
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, ReadCoilsResponse)
        # Compare whole bytes: a decoded reply holds the padding, one built locally may not.
        expected = (self.count + 7) // 8
        received = (len(response.values) + 7) // 8
        if received != expected:
            raise MalformedPDU(
                "reply byte count does not match the count asked",
                field="byte_count",
                value=received,
                allowed=range(expected, expected + 1),
            )

    def bits_of(self, response: ReadCoilsResponse) -> list[bool]:
        """The *count* bits this request asked for, without the padding."""
        return list(response.values[: self.count])


@dataclass(frozen=True, slots=True)
class ReadDiscreteInputsResponse(ReadCoilsResponse):
    """Reply to read discrete inputs; the same layout as
    [`ReadCoilsResponse`][aiortu.core.pdu.ReadCoilsResponse]."""

    function_code: ClassVar[int] = FunctionCode.READ_DISCRETE_INPUTS


@dataclass(frozen=True, slots=True)
class ReadDiscreteInputsRequest(ReadCoilsRequest):
    """Read `count` (1..2000) discrete inputs from protocol address `address`."""

    function_code: ClassVar[int] = FunctionCode.READ_DISCRETE_INPUTS
    response_class: ClassVar[type[Response]] = ReadDiscreteInputsResponse


def _coil_word(value: bool) -> int:
    return _COIL_ON if value else _COIL_OFF


def _decode_single_coil(cls: type[Request] | type[Response], pdu: bytes) -> tuple[int, bool]:
    """The address and the value of a 05 request or reply; only 0xFF00 and 0x0000 are values."""
    cls._expect_function_code(pdu)
    cls._expect_length(pdu, 5)
    address, word = unpack_registers(pdu, 1, 2)
    if word not in (_COIL_ON, _COIL_OFF):
        raise MalformedPDU(
            f"{cls.__name__}: coil value",
            field="value",
            value=word,
            allowed="0xFF00 (on) or 0x0000 (off)",
            exception_code=ExceptionCode.ILLEGAL_DATA_VALUE,
        )
    return address, word == _COIL_ON


@dataclass(frozen=True, slots=True)
class WriteSingleCoilResponse(Response):
    """Reply to write single coil: the request echoed, `address` and `value`.

    On the wire the value is 0xFF00 (on) or 0x0000 (off); decoding rejects any other word.
    """

    function_code: ClassVar[int] = FunctionCode.WRITE_SINGLE_COIL
    address: int
    value: bool

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", bool(self.value))
        self._check("address", self.address, ADDRESS_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address, _coil_word(self.value))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        address, value = _decode_single_coil(cls, pdu)
        return cls._build(lambda: cls(address, value))


@dataclass(frozen=True, slots=True)
class WriteSingleCoilRequest(Request):
    """Set the coil at protocol address `address` (0..65535) on (`True`) or off.

    `value` is a `bool`; it travels as 0xFF00 or 0x0000, and a decoded request with any
    other word raises MalformedPDU with exception code 03. May be broadcast.
    """

    function_code: ClassVar[int] = FunctionCode.WRITE_SINGLE_COIL
    response_class: ClassVar[type[Response]] = WriteSingleCoilResponse
    broadcastable: ClassVar[bool] = True
    address: int
    value: bool

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", bool(self.value))
        self._check("address", self.address, ADDRESS_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address, _coil_word(self.value))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        address, value = _decode_single_coil(cls, pdu)
        return cls._build(lambda: cls(address, value))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, WriteSingleCoilResponse)
        self._check_echo("address", response.address, self.address)
        self._check_echo("value", _coil_word(response.value), _coil_word(self.value))


@dataclass(frozen=True, slots=True)
class WriteMultipleCoilsResponse(Response):
    """Reply to write multiple coils: the `address` and the `count` (1..1968) written."""

    function_code: ClassVar[int] = FunctionCode.WRITE_MULTIPLE_COILS
    address: int
    count: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("count", self.count, _WRITE_BITS_COUNT)
        self._check("address + count", self.address + self.count, _END_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address, self.count)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)


@dataclass(frozen=True, slots=True)
class WriteMultipleCoilsRequest(Request):
    """Set 1..1968 consecutive coils from protocol address `address` to `values`.

    The count is `len(values)`, and `address + count` may not pass 65536. On the wire the
    bits are packed LSB first; a decoded request keeps exactly the count sent and ignores the
    padding bits of the last byte. May be broadcast.
    """

    function_code: ClassVar[int] = FunctionCode.WRITE_MULTIPLE_COILS
    response_class: ClassVar[type[Response]] = WriteMultipleCoilsResponse
    broadcastable: ClassVar[bool] = True
    address: int
    values: tuple[bool, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", tuple(bool(value) for value in self.values))
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("len(values)", len(self.values), _WRITE_BITS_COUNT)
        self._check("address + len(values)", self.address + len(self.values), _END_RANGE)

    @property
    def count(self) -> int:
        """The number of coils written."""
        return len(self.values)

    def encode(self) -> bytes:
        packed = pack_bits(self.values)
        return (
            bytes((self.function_code,))
            + pack_registers((self.address, len(self.values)))
            + bytes((len(packed),))
            + packed
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 7)
        address, count = unpack_registers(pdu, 1, 2)
        # The count is checked here rather than by the constructor because it decides how
        # many bits to unpack; an out-of-range count is exception 03 either way.
        if count not in _WRITE_BITS_COUNT:
            raise MalformedPDU(cls.__name__, field="count", value=count, allowed=_WRITE_BITS_COUNT)
        byte_count = pdu[5]
        expected = (count + 7) // 8
        if byte_count != expected:
            raise MalformedPDU(
                f"{cls.__name__}: byte count does not match the count",
                field="byte_count",
                value=byte_count,
                allowed=range(expected, expected + 1),
            )
        cls._expect_length(pdu, 6 + byte_count)
        return cls._build(lambda: cls(address, unpack_bits(pdu[6:])[:count]))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, WriteMultipleCoilsResponse)
        self._check_echo("address", response.address, self.address)
        self._check_echo("count", response.count, len(self.values))
