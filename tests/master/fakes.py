"""Scripted fake slaves on a virtual bus, for the master's tests.

A :class:`FakeSlave` reads request frames from its end of the line and answers each with
the step its script names for that request's index (default: :func:`answer`, the
standard reply of a small, predictable data model). Steps may stay silent, delay, send
raw bytes, or answer as another unit, which is how the tests build the line's faults.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field

import anyio
import anyio.abc

from aiortu.core.pdu import (
    DiagnosticsRequest,
    DiagnosticsResponse,
    GetCommEventCounterRequest,
    GetCommEventCounterResponse,
    GetCommEventLogRequest,
    GetCommEventLogResponse,
    MaskWriteRegisterRequest,
    MaskWriteRegisterResponse,
    RawPDU,
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDeviceIdentificationRequest,
    ReadDeviceIdentificationResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    ReadExceptionStatusRequest,
    ReadExceptionStatusResponse,
    ReadFifoQueueRequest,
    ReadFifoQueueResponse,
    ReadFileRecordRequest,
    ReadFileRecordResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    ReadWriteMultipleRegistersRequest,
    ReadWriteMultipleRegistersResponse,
    ReportServerIdRequest,
    ReportServerIdResponse,
    Request,
    WriteFileRecordRequest,
    WriteFileRecordResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
    decode_request,
)
from aiortu.core.rtu import FrameReceived, ReceiverState, Role, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.errors import ConnectionLost
from aiortu.line import Link
from aiortu.master import Master
from aiortu.testing import VirtualBus

__all__ = (
    "FakeSlave",
    "Seen",
    "answer",
    "coil_value",
    "line",
    "register_value",
    "silent",
    "standard_reply",
)

DEVICE_ID_OBJECTS = ((0, b"aiortu"), (1, b"FAKE-1"), (2, b"1.0"))


def register_value(unit: int, address: int) -> int:
    """The value the fake data model holds in a register: differs per unit and address."""
    return (unit * 1000 + address) & 0xFFFF


def coil_value(unit: int, address: int) -> bool:
    return (unit + address) % 3 == 0


def standard_reply(unit: int, request: Request) -> bytes:
    """The reply PDU of the fake data model to *request*."""
    match request:
        case ReadDiscreteInputsRequest(address=address, count=count):
            bits = tuple(coil_value(unit, address + i) for i in range(count))
            return ReadDiscreteInputsResponse(bits).encode()
        case ReadCoilsRequest(address=address, count=count):
            bits = tuple(coil_value(unit, address + i) for i in range(count))
            return ReadCoilsResponse(bits).encode()
        case ReadInputRegistersRequest(address=address, count=count):
            values = tuple(register_value(unit, address + i) ^ 0xFFFF for i in range(count))
            return ReadInputRegistersResponse(values).encode()
        case ReadHoldingRegistersRequest(address=address, count=count):
            values = tuple(register_value(unit, address + i) for i in range(count))
            return ReadHoldingRegistersResponse(values).encode()
        case WriteSingleCoilRequest(address=address, value=value):
            return WriteSingleCoilResponse(address, value).encode()
        case WriteSingleRegisterRequest(address=address, value=value):
            return WriteSingleRegisterResponse(address, value).encode()
        case WriteMultipleCoilsRequest(address=address, values=values):
            return WriteMultipleCoilsResponse(address, len(values)).encode()
        case WriteMultipleRegistersRequest(address=address, values=values):
            return WriteMultipleRegistersResponse(address, len(values)).encode()
        case MaskWriteRegisterRequest(address=address, and_mask=and_mask, or_mask=or_mask):
            return MaskWriteRegisterResponse(address, and_mask, or_mask).encode()
        case ReadWriteMultipleRegistersRequest(read_address=address, read_count=count):
            values = tuple(register_value(unit, address + i) for i in range(count))
            return ReadWriteMultipleRegistersResponse(values).encode()
        case ReadFifoQueueRequest(address=address):
            return ReadFifoQueueResponse((address, 2, 3)).encode()
        case ReadFileRecordRequest(sub_requests=subs):
            records = tuple(
                tuple(sub.file_number + sub.record_number + i for i in range(sub.record_length))
                for sub in subs
            )
            return ReadFileRecordResponse(records).encode()
        case WriteFileRecordRequest(records=records):
            return WriteFileRecordResponse(records).encode()
        case ReadExceptionStatusRequest():
            return ReadExceptionStatusResponse(0x55).encode()
        case DiagnosticsRequest(sub_function=sub_function, data=data):
            return DiagnosticsResponse(sub_function, data).encode()
        case GetCommEventCounterRequest():
            return GetCommEventCounterResponse(0, 7).encode()
        case GetCommEventLogRequest():
            return GetCommEventLogResponse(0, 7, 9, b"\x20\x00").encode()
        case ReportServerIdRequest():
            return ReportServerIdResponse(bytes((unit,)), True, b"fake").encode()
        case ReadDeviceIdentificationRequest(read_code=read_code, object_id=object_id):
            # Two objects per reply, so that a full read needs "more follows".
            start = next(i for i, (oid, _) in enumerate(DEVICE_ID_OBJECTS) if oid >= object_id)
            chunk = DEVICE_ID_OBJECTS[start : start + (1 if read_code == 4 else 2)]
            rest = () if read_code == 4 else DEVICE_ID_OBJECTS[start + 2 :]
            return ReadDeviceIdentificationResponse(
                read_code, 0x01, chunk, bool(rest), rest[0][0] if rest else 0
            ).encode()
        case RawPDU(function_code=code, data=data):
            return RawPDU(code, data[::-1]).encode()
    raise AssertionError(f"no standard reply to {request!r}")


@dataclass(frozen=True, slots=True)
class Seen:
    """A request frame the fake slave received."""

    unit: int
    request: Request
    time: float


Step = Callable[["FakeSlave", int, Request], Awaitable[None]]


async def answer(slave: FakeSlave, unit: int, request: Request) -> None:
    """The default step: the standard reply, from the unit asked."""
    await slave.reply(unit, standard_reply(unit, request))


async def silent(slave: FakeSlave, unit: int, request: Request) -> None:
    """A step that answers nothing."""


@dataclass
class FakeSlave:
    """A scripted slave on *stream*; run :meth:`run` in a task."""

    stream: anyio.abc.ByteStream
    units: frozenset[int] = frozenset(range(1, 248))
    script: dict[int, Step] = field(default_factory=dict)
    default: Step = answer
    seen: list[Seen] = field(default_factory=list)
    link: Link | None = None

    async def reply(self, unit: int, pdu: bytes) -> None:
        """Send *pdu* as a frame from *unit*."""
        await self.send_raw(encode_frame(unit, pdu))

    async def send_raw(self, data: bytes) -> None:
        """Put *data* on the line as it is."""
        assert self.link is not None
        await self.link.send(data)

    async def run(self) -> None:
        async with Link(
            self.stream, LineSettings(1_000_000), role=Role.SLAVE, units=range(248), frame_gap=0
        ) as link:
            self.link = link
            while True:
                try:
                    event = await link.receive()
                except ConnectionLost:
                    return  # the master closed its end
                if not isinstance(event, FrameReceived):
                    continue
                request = decode_request(event.pdu)
                index = len(self.seen)
                self.seen.append(Seen(event.unit, request, anyio.current_time()))
                if event.unit == 0 or event.unit not in self.units:
                    continue
                step = self.script.get(index, self.default)
                await step(self, event.unit, request)


async def until_idle(master: Master, slave: FakeSlave) -> None:
    """Wait until both receivers have left INIT, where they start by waiting for silence
    (20 ms in tolerant mode): a frame that comes sooner is taken for noise."""
    for _ in range(1000):
        if (
            slave.link is not None
            and slave.link.receiver.state is not ReceiverState.INIT
            and master.engine.link.receiver.state is not ReceiverState.INIT
        ):
            return
        await anyio.sleep(0.002)
    raise AssertionError("the receivers did not leave INIT within 2 s")


@contextlib.asynccontextmanager
async def line(
    *,
    script: dict[int, Step] | None = None,
    default: Step = answer,
    units: frozenset[int] = frozenset(range(1, 248)),
    **master_options: object,
) -> AsyncIterator[tuple[Master, FakeSlave, VirtualBus]]:
    """A master and a scripted fake slave on an unpaced two-port virtual bus."""
    bus = VirtualBus(2)
    slave = FakeSlave(bus.endpoints[1], units, script or {}, default)
    # A fast line: the link counts a request's wire time before the next send, and the
    # bus is unpaced, so a slow baud rate would only add idle time.
    options: dict[str, object] = {
        "settings": LineSettings(1_000_000),
        "frame_gap": 0.0,
        "timeout": 0.5,
    }
    options.update(master_options)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        async with Master(bus.endpoints[0], **options) as master:  # type: ignore[arg-type]
            await until_idle(master, slave)
            yield master, slave, bus
        tasks.cancel_scope.cancel()
