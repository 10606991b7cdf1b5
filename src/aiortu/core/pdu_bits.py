"""The PDUs of the bit tables: read coils (01), read discrete inputs (02), and the coil writes
(05, 0F).

Bits travel packed eight to a byte, the first bit in the least significant position, the
last byte padded with zeros. A decoded read response therefore holds every bit of its
bytes, padding included; :meth:`ReadCoilsRequest.bits_of` trims them to the count asked.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu import (
    ADDRESS_RANGE,
    Request,
    Response,
    pack_bits,
    register,
    unpack_bits,
)

__all__ = (
    "MAX_READ_BITS",
    "ReadCoilsRequest",
    "ReadCoilsResponse",
    "ReadDiscreteInputsRequest",
    "ReadDiscreteInputsResponse",
)

MAX_READ_BITS = 2000
"""The most coils or discrete inputs one read may ask for (0x7D0)."""

_READ_BITS_COUNT = range(1, MAX_READ_BITS + 1)
_READ_BITS_BYTE_COUNT = range(1, (MAX_READ_BITS + 7) // 8 + 1)


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
        cls._expect_min_length(pdu, 3)
        byte_count = pdu[1]
        if byte_count not in _READ_BITS_BYTE_COUNT:
            raise MalformedPDU(cls.__name__, field="byte_count", value=byte_count, allowed=_READ_BITS_BYTE_COUNT)
        cls._expect_length(pdu, 2 + byte_count)
        return cls._build(lambda: cls(unpack_bits(pdu[2:])))


@dataclass(frozen=True, slots=True)
class ReadCoilsRequest(Request):
    """Read *count* (1..2000) coils from protocol address *address*."""

    function_code: ClassVar[int] = FunctionCode.READ_COILS
    response_class: ClassVar[type[Response]] = ReadCoilsResponse
    address: int
    count: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("count", self.count, _READ_BITS_COUNT)
        self._check("address + count", self.address + self.count, range(ADDRESS_RANGE.stop + 1))

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + self.address.to_bytes(2, "big") + self.count.to_bytes(2, "big")

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_length(pdu, 5)
        return cls._build(lambda: cls(int.from_bytes(pdu[1:3], "big"), int.from_bytes(pdu[3:5], "big")))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, ReadCoilsResponse)
        expected = (self.count + 7) // 8
        if len(response.values) != expected * 8:
            raise MalformedPDU(
                "reply byte count does not match the count asked",
                field="byte_count",
                value=len(response.values) // 8,
                allowed=range(expected, expected + 1),
            )

    def bits_of(self, response: ReadCoilsResponse) -> list[bool]:
        """The *count* bits this request asked for, without the padding."""
        return list(response.values[: self.count])


@dataclass(frozen=True, slots=True)
class ReadDiscreteInputsResponse(ReadCoilsResponse):
    """Reply to read discrete inputs; the same layout as :class:`ReadCoilsResponse`."""

    function_code: ClassVar[int] = FunctionCode.READ_DISCRETE_INPUTS


@dataclass(frozen=True, slots=True)
class ReadDiscreteInputsRequest(ReadCoilsRequest):
    """Read *count* (1..2000) discrete inputs from protocol address *address*."""

    function_code: ClassVar[int] = FunctionCode.READ_DISCRETE_INPUTS
    response_class: ClassVar[type[Response]] = ReadDiscreteInputsResponse


register(ReadCoilsRequest)
register(ReadDiscreteInputsRequest)
