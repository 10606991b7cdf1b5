"""Hypothesis strategies for every PDU class of the bit and register tables (01-06, 0F-10, 16-18).

Each strategy builds valid objects over the whole range the spec allows, edges included.
``REQUEST_STRATEGIES`` and ``RESPONSE_STRATEGIES`` map each class to its strategy, so that
a test can fuzz all function codes at once; ``BITS_*`` and ``REGISTERS_*`` hold one module each.
"""

from __future__ import annotations

from types import ModuleType
from typing import TypeVar

from hypothesis import strategies as st
from hypothesis.strategies import SearchStrategy

from aiortu.core.pdu import (
    MAX_FIFO_COUNT,
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    MAX_READ_WRITE_WRITE_REGISTERS,
    MAX_WRITE_BITS,
    MAX_WRITE_REGISTERS,
    MaskWriteRegisterRequest,
    MaskWriteRegisterResponse,
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    ReadFifoQueueRequest,
    ReadFifoQueueResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    ReadWriteMultipleRegistersRequest,
    ReadWriteMultipleRegistersResponse,
    Request,
    Response,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
    unpack_bits,
    unpack_registers,
)
from aiortu.core.pdu import _bits as pdu_bits
from aiortu.core.pdu import _registers as pdu_registers

__all__ = (
    "BITS_REQUEST_STRATEGIES",
    "BITS_RESPONSE_STRATEGIES",
    "REGISTERS_REQUEST_STRATEGIES",
    "REGISTERS_RESPONSE_STRATEGIES",
    "REQUEST_STRATEGIES",
    "RESPONSE_STRATEGIES",
    "addresses",
    "bit_tuples",
    "mutations",
    "register_tuples",
    "registers",
    "replies_to",
    "spans",
)

ADDRESS_END = 0x10000

_T = TypeVar("_T")


def addresses() -> SearchStrategy[int]:
    """Protocol addresses 0..65535, with the ends drawn often."""
    return st.one_of(st.sampled_from((0, 1, ADDRESS_END - 1)), st.integers(0, ADDRESS_END - 1))


def registers() -> SearchStrategy[int]:
    """Register values 0..65535, with the ends drawn often."""
    return st.one_of(st.sampled_from((0, 1, 0x8000, 0xFFFF)), st.integers(0, 0xFFFF))


def _counts(maximum: int) -> SearchStrategy[int]:
    return st.one_of(st.sampled_from((1, maximum)), st.integers(1, maximum))


@st.composite
def spans(draw: st.DrawFn, maximum: int) -> tuple[int, int]:
    """An (address, count) pair with 1 <= count <= maximum and address + count <= 65536."""
    count = draw(_counts(maximum))
    last = ADDRESS_END - count
    address = draw(st.one_of(st.sampled_from((0, last)), st.integers(0, last)))
    return address, count


def _of_span(cls: type[_T], maximum: int) -> SearchStrategy[_T]:
    """Instances of a class built from (address, count), a read request or a write reply."""
    return spans(maximum).map(lambda span: cls(*span))  # type: ignore[call-arg]


def bit_tuples(count: int) -> SearchStrategy[tuple[bool, ...]]:
    """*count* random bits; drawn as bytes, far faster than thousands of booleans."""
    size = (count + 7) // 8
    return st.binary(min_size=size, max_size=size).map(lambda data: unpack_bits(data)[:count])


def _bits(maximum: int) -> SearchStrategy[tuple[bool, ...]]:
    return _counts(maximum).flatmap(bit_tuples)


def register_tuples(count: int) -> SearchStrategy[tuple[int, ...]]:
    """*count* random register values; drawn as bytes, far faster than a list of integers."""
    return st.binary(min_size=2 * count, max_size=2 * count).map(
        lambda data: unpack_registers(data, 0, count)
    )


def _register_list(maximum: int, min_size: int = 1) -> SearchStrategy[tuple[int, ...]]:
    ends = st.sampled_from((min_size, maximum))
    return st.one_of(ends, st.integers(min_size, maximum)).flatmap(register_tuples)


@st.composite
def _write_multiple_coils(draw: st.DrawFn) -> WriteMultipleCoilsRequest:
    address, count = draw(spans(MAX_WRITE_BITS))
    return WriteMultipleCoilsRequest(address, draw(bit_tuples(count)))


@st.composite
def _write_multiple_registers(draw: st.DrawFn) -> WriteMultipleRegistersRequest:
    address, count = draw(spans(MAX_WRITE_REGISTERS))
    return WriteMultipleRegistersRequest(address, draw(register_tuples(count)))


@st.composite
def _read_write_multiple_registers(draw: st.DrawFn) -> ReadWriteMultipleRegistersRequest:
    read_address, read_count = draw(spans(MAX_READ_REGISTERS))
    write_address, write_count = draw(spans(MAX_READ_WRITE_WRITE_REGISTERS))
    values = draw(register_tuples(write_count))
    return ReadWriteMultipleRegistersRequest(read_address, read_count, write_address, values)


_REQUESTS: dict[type[Request], SearchStrategy[Request]] = {
    ReadCoilsRequest: _of_span(ReadCoilsRequest, MAX_READ_BITS),
    ReadDiscreteInputsRequest: _of_span(ReadDiscreteInputsRequest, MAX_READ_BITS),
    WriteSingleCoilRequest: st.builds(WriteSingleCoilRequest, addresses(), st.booleans()),
    WriteMultipleCoilsRequest: _write_multiple_coils(),
    ReadHoldingRegistersRequest: _of_span(ReadHoldingRegistersRequest, MAX_READ_REGISTERS),
    ReadInputRegistersRequest: _of_span(ReadInputRegistersRequest, MAX_READ_REGISTERS),
    WriteSingleRegisterRequest: st.builds(WriteSingleRegisterRequest, addresses(), registers()),
    WriteMultipleRegistersRequest: _write_multiple_registers(),
    MaskWriteRegisterRequest: st.builds(
        MaskWriteRegisterRequest, addresses(), registers(), registers()
    ),
    ReadWriteMultipleRegistersRequest: _read_write_multiple_registers(),
    ReadFifoQueueRequest: st.builds(ReadFifoQueueRequest, addresses()),
}

_RESPONSES: dict[type[Response], SearchStrategy[Response]] = {
    ReadCoilsResponse: st.builds(ReadCoilsResponse, _bits(MAX_READ_BITS)),
    ReadDiscreteInputsResponse: st.builds(ReadDiscreteInputsResponse, _bits(MAX_READ_BITS)),
    WriteSingleCoilResponse: st.builds(WriteSingleCoilResponse, addresses(), st.booleans()),
    WriteMultipleCoilsResponse: _of_span(WriteMultipleCoilsResponse, MAX_WRITE_BITS),
    ReadHoldingRegistersResponse: st.builds(
        ReadHoldingRegistersResponse, _register_list(MAX_READ_REGISTERS)
    ),
    ReadInputRegistersResponse: st.builds(
        ReadInputRegistersResponse, _register_list(MAX_READ_REGISTERS)
    ),
    WriteSingleRegisterResponse: st.builds(WriteSingleRegisterResponse, addresses(), registers()),
    WriteMultipleRegistersResponse: _of_span(WriteMultipleRegistersResponse, MAX_WRITE_REGISTERS),
    MaskWriteRegisterResponse: st.builds(
        MaskWriteRegisterResponse, addresses(), registers(), registers()
    ),
    ReadWriteMultipleRegistersResponse: st.builds(
        ReadWriteMultipleRegistersResponse, _register_list(MAX_READ_REGISTERS)
    ),
    ReadFifoQueueResponse: st.builds(
        ReadFifoQueueResponse, _register_list(MAX_FIFO_COUNT, min_size=0)
    ),
}

REQUEST_STRATEGIES: dict[type, SearchStrategy[Request]] = dict(_REQUESTS)
"""Every request class of pdu_bits and pdu_registers, with a strategy of valid instances."""

RESPONSE_STRATEGIES: dict[type, SearchStrategy[Response]] = dict(_RESPONSES)
"""Every response class of pdu_bits and pdu_registers, with a strategy of valid instances."""


def _of_module(
    strategies: dict[type, SearchStrategy[_T]], module: ModuleType
) -> dict[type, SearchStrategy[_T]]:
    return {cls: s for cls, s in strategies.items() if vars(module).get(cls.__name__) is cls}


BITS_REQUEST_STRATEGIES = _of_module(REQUEST_STRATEGIES, pdu_bits)
BITS_RESPONSE_STRATEGIES = _of_module(RESPONSE_STRATEGIES, pdu_bits)
REGISTERS_REQUEST_STRATEGIES = _of_module(REQUEST_STRATEGIES, pdu_registers)
REGISTERS_RESPONSE_STRATEGIES = _of_module(RESPONSE_STRATEGIES, pdu_registers)


def replies_to(request: Request) -> SearchStrategy[Response]:
    """Valid replies that answer *request*: the echo of a write, the count asked of a read."""
    if isinstance(request, ReadCoilsRequest):
        cls = request.response_class
        return bit_tuples(request.count).map(cls)
    if isinstance(request, ReadHoldingRegistersRequest | ReadWriteMultipleRegistersRequest):
        cls = request.response_class
        count = (
            request.count
            if isinstance(request, ReadHoldingRegistersRequest)
            else request.read_count
        )
        return register_tuples(count).map(cls)
    if isinstance(request, WriteSingleCoilRequest):
        return st.just(WriteSingleCoilResponse(request.address, request.value))
    if isinstance(request, WriteSingleRegisterRequest):
        return st.just(WriteSingleRegisterResponse(request.address, request.value))
    if isinstance(request, WriteMultipleCoilsRequest):
        return st.just(WriteMultipleCoilsResponse(request.address, request.count))
    if isinstance(request, WriteMultipleRegistersRequest):
        return st.just(WriteMultipleRegistersResponse(request.address, request.count))
    if isinstance(request, MaskWriteRegisterRequest):
        return st.just(
            MaskWriteRegisterResponse(request.address, request.and_mask, request.or_mask)
        )
    if isinstance(request, ReadFifoQueueRequest):
        return RESPONSE_STRATEGIES[ReadFifoQueueResponse]
    raise TypeError(f"no replies for {type(request).__name__}")


@st.composite
def mutations(draw: st.DrawFn, pdu: bytes) -> bytes:
    """*pdu* truncated, extended, with a byte flipped, or with a byte replaced."""
    kind = draw(st.sampled_from(("truncate", "extend", "flip", "replace")))
    if kind == "truncate":
        return pdu[: draw(st.integers(0, len(pdu) - 1))]
    if kind == "extend":
        return pdu + draw(st.binary(min_size=1, max_size=8))
    index = draw(st.integers(0, len(pdu) - 1))
    change = draw(st.integers(0 if kind == "replace" else 1, 255))
    byte = pdu[index] ^ change if kind == "flip" else change
    return pdu[:index] + bytes((byte,)) + pdu[index + 1 :]
