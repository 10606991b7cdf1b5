"""`aiortu monitor --framing ascii`: the bus decoder's meanings for Modbus ASCII traffic.

The bytes of the line go through the spec's ASCII receiver
([`AsciiReceiver`][aiortu.core.ascii.AsciiReceiver], whose inter-character timeout ends a frame
whose characters stop coming); each frame whose LRC checks is decoded by the same
[`BusDecoder`][aiortu.core.rtu.BusDecoder] as RTU frames (requests paired with their replies),
and the characters that make no frame are shown with the receiver's one-sentence reason.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import anyio
import anyio.abc

from aiortu.core.ascii import AsciiDiscardReason, AsciiFrameReceived, AsciiReceiver
from aiortu.core.ascii import AsciiReceiverOutput as _Output
from aiortu.core.rtu import (
    BusDecoder,
    CrcStatus,
    DecodedFrame,
    DiscardReason,
    FrameDiscarded,
    FrameReceived,
    crc16_bytes,
)
from aiortu.core.serial import LineSettings

__all__ = ("AsciiBusDecoder", "monitor_ascii")


class AsciiBusDecoder:
    """Decodes the characters of a Modbus ASCII bus into
    [`DecodedFrame`][aiortu.core.rtu.DecodedFrame]s (see the module docstring). A frame's
    `frame` is its bytes as decoded from hex (unit, PDU, LRC); its `crc` says whether the LRC
    checked."""

    def __init__(self, settings: LineSettings | None = None) -> None:
        self.receiver = AsciiReceiver(settings)
        self.decoder = BusDecoder()

    def feed(self, data: bytes, now: float) -> list[DecodedFrame]:
        """The records of the frames `data`, arrived at `now`, ends."""
        return [self._decode(output) for output in self.receiver.feed(data, now)]

    def expire(self, now: float) -> list[DecodedFrame]:
        """The records of what the inter-character timeout ends by `now`."""
        return [self._decode(output) for output in self.receiver.expire(now)]

    def _decode(self, output: _Output) -> DecodedFrame:
        if isinstance(output, AsciiFrameReceived):
            body = output.frame[:-1]  # the LRC off, a CRC on: the RTU frame it carries
            event = FrameReceived(body + crc16_bytes(body), output.start, output.end)
            return dataclasses.replace(self.decoder.feed(event), frame=output.frame)
        # Told as noise to the decoder, so that it forgets a request whose reply this may be.
        record = self.decoder.feed(
            FrameDiscarded(output.data, DiscardReason.NOISE, output.start, output.end)
        )
        lrc = output.reason is AsciiDiscardReason.LRC
        text = output.data.decode("ascii", "backslashreplace").rstrip("\r\n")
        return dataclasses.replace(
            record,
            crc=CrcStatus.ERROR if lrc else CrcStatus.UNCHECKED,
            description=f"{output.detail}: {text}",
            discard_reason=None,
        )


async def monitor_ascii(
    stream: anyio.abc.ByteStream,
    settings: LineSettings,
    clock: Callable[[], float],
    emit: Callable[[DecodedFrame], None],
) -> None:
    """Read `stream` until it ends, emitting a record for each frame and each discard."""
    decoder = AsciiBusDecoder(settings)
    while True:
        deadline = decoder.receiver.next_deadline()
        data = b""
        with anyio.move_on_after(None if deadline is None else max(deadline - clock(), 0)):
            data = await stream.receive()
        now = clock()
        records = decoder.feed(data, now) if data else decoder.expire(now)
        for record in records:
            emit(record)
