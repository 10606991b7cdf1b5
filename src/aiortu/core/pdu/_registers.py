"""The PDUs of the register tables: read holding (03) and input (04) registers, and the
register writes (06, 10, 16, 17) and the FIFO queue (18).

Registers are 16-bit big-endian words on the wire and `int` 0..65535 here; typed values
(floats, 32-bit integers, strings) are converted by [`aiortu.core.model`][aiortu.core.model].
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu._base import (
    ADDRESS_RANGE,
    REGISTER_RANGE,
    RawPDU,
    Request,
    Response,
    pack_registers,
    unpack_registers,
)

__all__ = (
    "MAX_FIFO_COUNT",
    "MAX_READ_REGISTERS",
    "MAX_READ_WRITE_WRITE_REGISTERS",
    "MAX_WRITE_REGISTERS",
    "MaskWriteRegisterRequest",
    "MaskWriteRegisterResponse",
    "RawRegisterRead",
    "ReadFifoQueueRequest",
    "ReadFifoQueueResponse",
    "ReadHoldingRegistersRequest",
    "ReadHoldingRegistersResponse",
    "ReadInputRegistersRequest",
    "ReadInputRegistersResponse",
    "ReadWriteMultipleRegistersRequest",
    "ReadWriteMultipleRegistersResponse",
    "WriteMultipleRegistersRequest",
    "WriteMultipleRegistersResponse",
    "WriteSingleRegisterRequest",
    "WriteSingleRegisterResponse",
)

MAX_READ_REGISTERS = 125
"""The most registers one read may ask for (0x7D), also the read part of 17."""

MAX_WRITE_REGISTERS = 123
"""The most registers one write multiple registers (10) may set (0x7B)."""

MAX_READ_WRITE_WRITE_REGISTERS = 121
"""The most registers the write part of read/write multiple registers (17) may set (0x79)."""

MAX_FIFO_COUNT = 31
"""The most values a FIFO queue may hold in a read FIFO queue (18) reply."""

_READ_REGISTERS_COUNT = range(1, MAX_READ_REGISTERS + 1)
_WRITE_REGISTERS_COUNT = range(1, MAX_WRITE_REGISTERS + 1)
_READ_WRITE_WRITE_COUNT = range(1, MAX_READ_WRITE_WRITE_REGISTERS + 1)
_FIFO_COUNT = range(MAX_FIFO_COUNT + 1)
_END_RANGE = range(ADDRESS_RANGE.stop + 1)
_REGISTER_READ_CODES = range(
    FunctionCode.READ_HOLDING_REGISTERS, FunctionCode.READ_INPUT_REGISTERS + 1
)
_ADDRESS_COUNT = struct.Struct(">HH")


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
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 4)
        byte_count = pdu[1]
        if byte_count % 2 or byte_count // 2 not in _READ_REGISTERS_COUNT:
            raise MalformedPDU(
                cls.__name__,
                field="byte_count",
                value=byte_count,
                allowed=range(2, 2 * MAX_READ_REGISTERS + 1, 2),
            )
        cls._expect_length(pdu, 2 + byte_count)
        return cls._build(lambda: cls(unpack_registers(pdu, 2, byte_count // 2)))


@dataclass(frozen=True, slots=True)
class ReadHoldingRegistersRequest(Request):
    """Read `count` (1..125) holding registers from protocol address `address`."""

    function_code: ClassVar[int] = FunctionCode.READ_HOLDING_REGISTERS
    response_class: ClassVar[type[Response]] = ReadHoldingRegistersResponse
    address: int
    count: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("count", self.count, _READ_REGISTERS_COUNT)
        self._check("address + count", self.address + self.count, range(ADDRESS_RANGE.stop + 1))

    def encode(self) -> bytes:
        return self._encode_words(self.address, self.count)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)

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
class RawRegisterRead(RawPDU):
    """A read of holding (03) or input (04) registers kept as its PDU bytes, for a caller that
    forwards PDUs as they come, such as the line server.

    It encodes to the bytes it was made of, and the master hands its usual reply over as a
    [`RawPDU`][aiortu.core.pdu.RawPDU] of the reply's bytes as they came, not decoded. Any
    reply is checked as a register read's is (the function code, a byte count of twice the
    count asked, and that many bytes), so a reply answers it exactly when it answers the
    [`ReadHoldingRegistersRequest`][aiortu.core.pdu.ReadHoldingRegistersRequest] (or
    [`ReadInputRegistersRequest`][aiortu.core.pdu.ReadInputRegistersRequest]) of the same
    bytes. Building one checks what that request's constructor checks, raising
    [`InvalidRequest`][aiortu.errors.InvalidRequest]:

        >>> RawRegisterRead(0x03, bytes.fromhex("006b 0003")).count
        3
    """

    def __post_init__(self) -> None:
        RawPDU.__post_init__(self)
        self._check("function_code", self.function_code, _REGISTER_READ_CODES)
        self._check("len(data)", len(self.data), range(4, 5))
        address, count = _ADDRESS_COUNT.unpack(self.data)
        self._check("count", count, _READ_REGISTERS_COUNT)
        self._check("address + count", address + count, _END_RANGE)

    @property
    def count(self) -> int:
        """The number of registers asked for."""
        return int(_ADDRESS_COUNT.unpack(self.data)[1])

    def check_response(self, response: Response) -> None:
        if response.function_code != self.function_code:
            raise MalformedPDU("reply function code differs from the request's")
        pdu = response.encode()
        size = 2 * self.count
        byte_count = pdu[1] if len(pdu) > 1 else None
        if byte_count != size:
            raise MalformedPDU(
                "reply register count does not match the count asked",
                field="byte_count",
                value=byte_count,
                allowed=range(size, size + 1),
            )
        if len(pdu) != 2 + size:
            raise MalformedPDU(
                "reply length does not match its byte count",
                field="length",
                value=len(pdu),
                allowed=range(2 + size, 3 + size),
            )


@dataclass(frozen=True, slots=True)
class ReadInputRegistersResponse(ReadHoldingRegistersResponse):
    """Reply to read input registers; the same layout as
    [`ReadHoldingRegistersResponse`][aiortu.core.pdu.ReadHoldingRegistersResponse]."""

    function_code: ClassVar[int] = FunctionCode.READ_INPUT_REGISTERS


@dataclass(frozen=True, slots=True)
class ReadInputRegistersRequest(ReadHoldingRegistersRequest):
    """Read `count` (1..125) input registers from protocol address `address`."""

    function_code: ClassVar[int] = FunctionCode.READ_INPUT_REGISTERS
    response_class: ClassVar[type[Response]] = ReadInputRegistersResponse


@dataclass(frozen=True, slots=True)
class WriteSingleRegisterResponse(Response):
    """Reply to write single register: the request echoed, `address` and `value` (0..65535)."""

    function_code: ClassVar[int] = FunctionCode.WRITE_SINGLE_REGISTER
    address: int
    value: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("value", self.value, REGISTER_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address, self.value)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)


@dataclass(frozen=True, slots=True)
class WriteSingleRegisterRequest(Request):
    """Write `value` (0..65535) to the holding register at `address` (0..65535).

    May be broadcast.
    """

    function_code: ClassVar[int] = FunctionCode.WRITE_SINGLE_REGISTER
    response_class: ClassVar[type[Response]] = WriteSingleRegisterResponse
    broadcastable: ClassVar[bool] = True
    address: int
    value: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("value", self.value, REGISTER_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address, self.value)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, WriteSingleRegisterResponse)
        self._check_echo("address", response.address, self.address)
        self._check_echo("value", response.value, self.value)


@dataclass(frozen=True, slots=True)
class WriteMultipleRegistersResponse(Response):
    """Reply to write multiple registers: the `address` and the `count` (1..123) written."""

    function_code: ClassVar[int] = FunctionCode.WRITE_MULTIPLE_REGISTERS
    address: int
    count: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("count", self.count, _WRITE_REGISTERS_COUNT)
        self._check("address + count", self.address + self.count, _END_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address, self.count)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        return cls._decode_words(pdu, 2)


def _decode_write_count(
    cls: type[Request], pdu: bytes, offset: int, allowed: range, field: str
) -> int:
    """Check the count at `offset` and the byte count after it; return the count.

    Both are the peer's quantity errors, exception 03. The count is checked here, before
    the constructor sees it, because it decides how many registers to unpack.
    """
    (count,) = unpack_registers(pdu, offset, 1)
    if count not in allowed:
        raise MalformedPDU(cls.__name__, field=field, value=count, allowed=allowed)
    byte_count = pdu[offset + 2]
    if byte_count != 2 * count:
        raise MalformedPDU(
            f"{cls.__name__}: byte count does not match the count",
            field="byte_count",
            value=byte_count,
            allowed=range(2 * count, 2 * count + 1),
        )
    cls._expect_length(pdu, offset + 3 + byte_count)
    return count


@dataclass(frozen=True, slots=True)
class WriteMultipleRegistersRequest(Request):
    """Write 1..123 `values` (each 0..65535) to consecutive holding registers from `address`.

    The count is `len(values)`, and `address + count` may not pass 65536. May be
    broadcast.
    """

    function_code: ClassVar[int] = FunctionCode.WRITE_MULTIPLE_REGISTERS
    response_class: ClassVar[type[Response]] = WriteMultipleRegistersResponse
    broadcastable: ClassVar[bool] = True
    address: int
    values: tuple[int, ...]

    def __post_init__(self) -> None:
        values = tuple(self.values)
        object.__setattr__(self, "values", values)
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("len(values)", len(values), _WRITE_REGISTERS_COUNT)
        self._check_values("values", values, REGISTER_RANGE)
        self._check("address + len(values)", self.address + len(values), _END_RANGE)

    @property
    def count(self) -> int:
        """The number of registers written."""
        return len(self.values)

    def encode(self) -> bytes:
        return (
            bytes((self.function_code,))
            + pack_registers((self.address, len(self.values)))
            + bytes((2 * len(self.values),))
            + pack_registers(self.values)
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 8)
        (address,) = unpack_registers(pdu, 1, 1)
        count = _decode_write_count(cls, pdu, 3, _WRITE_REGISTERS_COUNT, "count")
        return cls._build(lambda: cls(address, unpack_registers(pdu, 6, count)))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, WriteMultipleRegistersResponse)
        self._check_echo("address", response.address, self.address)
        self._check_echo("count", response.count, len(self.values))


@dataclass(frozen=True, slots=True)
class MaskWriteRegisterResponse(Response):
    """Reply to mask write register: the request echoed, `address`, `and_mask`, `or_mask`."""

    function_code: ClassVar[int] = FunctionCode.MASK_WRITE_REGISTER
    address: int
    and_mask: int
    or_mask: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("and_mask", self.and_mask, REGISTER_RANGE)
        self._check("or_mask", self.or_mask, REGISTER_RANGE)

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + pack_registers(
            (self.address, self.and_mask, self.or_mask)
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 7)
        return cls._build(lambda: cls(*unpack_registers(pdu, 1, 3)))


@dataclass(frozen=True, slots=True)
class MaskWriteRegisterRequest(Request):
    """Change the bits of the holding register at `address` through two 16-bit masks.

    The register becomes `(current AND and_mask) OR (or_mask AND NOT and_mask)`; see
    [`apply`][aiortu.core.pdu.MaskWriteRegisterRequest.apply]. Both masks are 0..65535.
    May be broadcast.
    """

    function_code: ClassVar[int] = FunctionCode.MASK_WRITE_REGISTER
    response_class: ClassVar[type[Response]] = MaskWriteRegisterResponse
    broadcastable: ClassVar[bool] = True
    address: int
    and_mask: int
    or_mask: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)
        self._check("and_mask", self.and_mask, REGISTER_RANGE)
        self._check("or_mask", self.or_mask, REGISTER_RANGE)

    def apply(self, current: int) -> int:
        """The register's new value, given its `current` value (0..65535)."""
        return (current & self.and_mask) | (self.or_mask & ~self.and_mask & 0xFFFF)

    def encode(self) -> bytes:
        return bytes((self.function_code,)) + pack_registers(
            (self.address, self.and_mask, self.or_mask)
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 7)
        return cls._build(lambda: cls(*unpack_registers(pdu, 1, 3)))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, MaskWriteRegisterResponse)
        self._check_echo("address", response.address, self.address)
        self._check_echo("and_mask", response.and_mask, self.and_mask)
        self._check_echo("or_mask", response.or_mask, self.or_mask)


@dataclass(frozen=True, slots=True)
class ReadWriteMultipleRegistersResponse(ReadHoldingRegistersResponse):
    """Reply to read/write multiple registers: the 1..125 registers read.

    The same layout as
    [`ReadHoldingRegistersResponse`][aiortu.core.pdu.ReadHoldingRegistersResponse].
    """

    function_code: ClassVar[int] = FunctionCode.READ_WRITE_MULTIPLE_REGISTERS


@dataclass(frozen=True, slots=True)
class ReadWriteMultipleRegistersRequest(Request):
    """Write 1..121 `values` from `write_address`, then read `read_count` (1..125) registers
    from `read_address`, in one exchange.

    The slave performs the write before the read. Neither range may pass address 65535.
    Not broadcastable: it reads.
    """

    function_code: ClassVar[int] = FunctionCode.READ_WRITE_MULTIPLE_REGISTERS
    response_class: ClassVar[type[Response]] = ReadWriteMultipleRegistersResponse
    read_address: int
    read_count: int
    write_address: int
    values: tuple[int, ...]

    def __post_init__(self) -> None:
        values = tuple(self.values)
        object.__setattr__(self, "values", values)
        self._check("read_address", self.read_address, ADDRESS_RANGE)
        self._check("write_address", self.write_address, ADDRESS_RANGE)
        # Quantities before address ranges: a decoded request wrong in both must get 03.
        self._check("read_count", self.read_count, _READ_REGISTERS_COUNT)
        self._check("len(values)", len(values), _READ_WRITE_WRITE_COUNT)
        self._check_values("values", values, REGISTER_RANGE)
        self._check("read_address + read_count", self.read_address + self.read_count, _END_RANGE)
        self._check("write_address + len(values)", self.write_address + len(values), _END_RANGE)

    @property
    def write_count(self) -> int:
        """The number of registers written."""
        return len(self.values)

    def encode(self) -> bytes:
        return (
            bytes((self.function_code,))
            + pack_registers(
                (self.read_address, self.read_count, self.write_address, len(self.values))
            )
            + bytes((2 * len(self.values),))
            + pack_registers(self.values)
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 12)
        read_address, read_count, write_address = unpack_registers(pdu, 1, 3)
        count = _decode_write_count(cls, pdu, 7, _READ_WRITE_WRITE_COUNT, "write_count")
        return cls._build(
            lambda: cls(read_address, read_count, write_address, unpack_registers(pdu, 10, count))
        )

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, ReadWriteMultipleRegistersResponse)
        if len(response.values) != self.read_count:
            raise MalformedPDU(
                "reply register count does not match the count asked",
                field="byte_count",
                value=2 * len(response.values),
                allowed=range(2 * self.read_count, 2 * self.read_count + 1),
            )


@dataclass(frozen=True, slots=True)
class ReadFifoQueueResponse(Response):
    """Reply to read FIFO queue: the 0..31 `values` queued, oldest first.

    On the wire: a 2-byte byte count (`2 + 2 * len(values)`), a 2-byte FIFO count, then
    the values.
    """

    function_code: ClassVar[int] = FunctionCode.READ_FIFO_QUEUE
    values: tuple[int, ...]

    def __post_init__(self) -> None:
        values = tuple(self.values)
        object.__setattr__(self, "values", values)
        self._check("len(values)", len(values), _FIFO_COUNT)
        self._check_values("values", values, REGISTER_RANGE)

    def encode(self) -> bytes:
        count = len(self.values)
        return bytes((self.function_code,)) + pack_registers((2 + 2 * count, count, *self.values))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 5)
        byte_count, fifo_count = unpack_registers(pdu, 1, 2)
        if fifo_count not in _FIFO_COUNT:
            raise MalformedPDU(
                cls.__name__, field="fifo_count", value=fifo_count, allowed=_FIFO_COUNT
            )
        expected = 2 + 2 * fifo_count
        if byte_count != expected:
            raise MalformedPDU(
                f"{cls.__name__}: byte count does not match the FIFO count",
                field="byte_count",
                value=byte_count,
                allowed=range(expected, expected + 1),
            )
        cls._expect_length(pdu, 3 + byte_count)
        return cls._build(lambda: cls(unpack_registers(pdu, 5, fifo_count)))


@dataclass(frozen=True, slots=True)
class ReadFifoQueueRequest(Request):
    """Read the FIFO queue whose pointer register is at `address` (0..65535).

    The reply holds up to 31 values and reading leaves them queued. Nothing in the request bounds
    the reply's count, so [`check_response`][aiortu.core.pdu.Request.check_response] checks the
    reply's class only.
    """

    function_code: ClassVar[int] = FunctionCode.READ_FIFO_QUEUE
    response_class: ClassVar[type[Response]] = ReadFifoQueueResponse
    address: int

    def __post_init__(self) -> None:
        self._check("address", self.address, ADDRESS_RANGE)

    def encode(self) -> bytes:
        return self._encode_words(self.address)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 3)
        return cls._build(lambda: cls(*unpack_registers(pdu, 1, 1)))
