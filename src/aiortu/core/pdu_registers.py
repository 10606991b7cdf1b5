"""The PDUs of the register tables: read holding (03) and input (04) registers, and the
register writes (06, 10, 16, 17) and the FIFO queue (18).

Registers are 16-bit big-endian words on the wire and ``int`` 0..65535 here; typed values
(floats, 32-bit integers, strings) are converted by :mod:`aiortu.core.values`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu import (
    ADDRESS_RANGE,
    REGISTER_RANGE,
    Request,
    Response,
    pack_registers,
    register,
    unpack_registers,
)

__all__ = (
    "MAX_READ_REGISTERS",
    "ReadHoldingRegistersRequest",
    "ReadHoldingRegistersResponse",
    "ReadInputRegistersRequest",
    "ReadInputRegistersResponse",
)

MAX_READ_REGISTERS = 125
"""The most registers one read may ask for (0x7D)."""

_READ_REGISTERS_COUNT = range(1, MAX_READ_REGISTERS + 1)


@dataclass(frozen=True, slots=True)
class ReadHoldingRegistersResponse(Response):
    """Reply to read holding registers: 1..125 register values."""

    function_code: ClassVar[int] = FunctionCode.READ_HOLDING_REGISTERS
    values: tuple[int, ...]

    def __post_init__(self) -> None:
        values = tuple(self.values)
        object.__setattr__(self, "values", values)
        self._check("len(values)", len(values), _READ_REGISTERS_COUNT)
        self._check_values("values", values, REGISTER_RANGE)

    def encode(self) -> bytes:
        return bytes((self.function_code, 2 * len(self.values))) + pack_registers(self.values)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_min_length(pdu, 4)
        byte_count = pdu[1]
        if byte_count % 2 or byte_count // 2 not in _READ_REGISTERS_COUNT:
            raise MalformedPDU(
                cls.__name__, field="byte_count", value=byte_count, allowed=range(2, 2 * MAX_READ_REGISTERS + 1, 2)
            )
        cls._expect_length(pdu, 2 + byte_count)
        return cls._build(lambda: cls(unpack_registers(pdu, 2, byte_count // 2)))


@dataclass(frozen=True, slots=True)
class ReadHoldingRegistersRequest(Request):
    """Read *count* (1..125) holding registers from protocol address *address*."""

    function_code: ClassVar[int] = FunctionCode.READ_HOLDING_REGISTERS
    response_class: ClassVar[type[Response]] = ReadHoldingRegistersResponse
    address: int
    count: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("count", self.count, _READ_REGISTERS_COUNT)
        self._check("address + count", self.address + self.count, range(ADDRESS_RANGE.stop + 1))

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + pack_registers((self.address, self.count))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_length(pdu, 5)
        return cls._build(lambda: cls(*unpack_registers(pdu, 1, 2)))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, ReadHoldingRegistersResponse)
        if len(response.values) != self.count:
            raise MalformedPDU(
                "reply register count does not match the count asked",
                field="byte_count",
                value=2 * len(response.values),
                allowed=range(2 * self.count, 2 * self.count + 1),
            )


@dataclass(frozen=True, slots=True)
class ReadInputRegistersResponse(ReadHoldingRegistersResponse):
    """Reply to read input registers; the same layout as :class:`ReadHoldingRegistersResponse`."""

    function_code: ClassVar[int] = FunctionCode.READ_INPUT_REGISTERS


@dataclass(frozen=True, slots=True)
class ReadInputRegistersRequest(ReadHoldingRegistersRequest):
    """Read *count* (1..125) input registers from protocol address *address*."""

    function_code: ClassVar[int] = FunctionCode.READ_INPUT_REGISTERS
    response_class: ClassVar[type[Response]] = ReadInputRegistersResponse


register(ReadHoldingRegistersRequest)
register(ReadInputRegistersRequest)
