"""Modbus TCP for a master: a byte stream of RTU frames carried as MBAP ADUs.

The master, its engine and its state machine speak RTU frames (unit, PDU, CRC). Rather than
teach each of them a second framing, [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream]
translates at the edge, as a byte stream over a TCP connection:

- each frame written goes out as one ADU: the unit and the PDU behind an MBAP header with the
  next transaction id, the CRC dropped (TCP checks the bytes);
- each ADU received whose transaction id is the one outstanding comes back from `receive()` as
  one RTU frame, its CRC computed; any other ADU (a late reply to a request that timed out, an
  id never sent) is dropped and counted in
  [`ModbusTcpCounters`][aiortu.transport.ModbusTcpCounters]. A late reply therefore never
  reaches a later request, whatever it looks like.

Every `receive()` returns exactly one whole frame, and there is no wire to keep quiet: the
stream says so by [`whole_frames`][aiortu.transport.FramedStream], and the
[`Link`][aiortu.line.Link] then ends each frame at once (even of a function code whose length
cannot be told from its first bytes), keeps no t3.5 before a request, and starts the response
timeout when the write returned. Function codes meant for serial lines only (diagnostics,
the comm event counter) go out as asked: whether the server answers them is the server's choice.

A header that breaks the spec (protocol id other than 0, a bad length) leaves no way to find
where the next ADU starts: the stream closes and `receive()` raises
`anyio.BrokenResourceError`, which a master takes as a lost connection and reconnects.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu._log import get_logger
from aiortu.core.codes import MBAP_UNIT_IDS, UnitIds
from aiortu.core.mbap import Adu, AduDecoder, MalformedHeader, encode_adu
from aiortu.core.rtu import crc16
from aiortu.errors import InvalidValue

__all__ = ("FramedStream", "ModbusTcpCounters", "ModbusTcpStream")

_log = get_logger(__name__)

NONE_OUTSTANDING = -1
"""The transaction id outstanding when none is: no reply matches it."""


def request_adu(counters: ModbusTcpCounters, item: bytes) -> tuple[int, bytes]:
    """The transaction id and the ADU that carry the RTU frame `item` (its CRC dropped), the
    id taken from `counters` and the request counted."""
    if len(item) < 4:
        raise InvalidValue("len(item)", len(item), "at least 4 (unit, PDU and CRC)")
    transaction_id = take_transaction_id(counters)
    return transaction_id, encode_adu(transaction_id, item[0], bytes(item[1:-2]))


def take_transaction_id(counters: ModbusTcpCounters) -> int:
    """The transaction id of a request about to go, taken from `counters`; the request counted."""
    transaction_id = counters.next_transaction_id
    counters.next_transaction_id = (transaction_id + 1) & 0xFFFF
    counters.requests += 1
    return transaction_id


def reply_taken(counters: ModbusTcpCounters, outstanding: int, transaction_id: int) -> bool:
    """Whether a reply with `transaction_id` answers the transaction `outstanding`: counted as
    a reply if so, else as dropped (a late reply, an id never sent)."""
    if transaction_id != outstanding:
        counters.dropped += 1
        _log.debug(
            "dropped a reply with transaction id %d (waiting for %d)",
            transaction_id,
            outstanding,
        )
        return False
    counters.replies += 1
    return True


def reply_frame(counters: ModbusTcpCounters, outstanding: int, adu: Adu) -> bytes | None:
    """The RTU frame (CRC computed) of `adu` when it answers the transaction `outstanding`,
    counted as a reply; else None, counted as dropped (a late reply, an id never sent)."""
    if not reply_taken(counters, outstanding, adu.transaction_id):
        return None
    frame = bytes((adu.unit,)) + adu.pdu
    crc = crc16(frame)
    return frame + bytes((crc & 0xFF, crc >> 8))


@runtime_checkable
class FramedStream(Protocol):
    """A byte stream that knows where its frames end, and which unit ids they carry.

    Where `whole_frames` is true, every `receive()` returns exactly one whole frame, and
    `send()` carries a frame with no wire time to wait for. [`Link`][aiortu.line.Link] checks for
    it once, when it is made. A [`Master`][aiortu.master.Master] takes its unit ids from
    `unit_ids`; any other stream carries RTU frames of a serial line
    ([`SERIAL_UNIT_IDS`][aiortu.core.codes.SERIAL_UNIT_IDS]).
    """

    @property
    def whole_frames(self) -> bool:
        """Whether each `receive()` returns exactly one whole frame."""
        ...

    @property
    def unit_ids(self) -> UnitIds:
        """The unit ids the stream's framing carries."""
        ...


@dataclass(slots=True)
class ModbusTcpCounters:
    """What a [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] sent and received.

    One object may be shared by the streams of successive connections to the same server
    (a master's reconnects do): the counts go on, and so do the transaction ids, so that a
    reply to a request sent before a reconnect cannot match one sent after it.
    """

    next_transaction_id: int = 0
    """The transaction id of the next request (0..65535, wrapping)."""
    requests: int = 0
    """ADUs sent."""
    replies: int = 0
    """ADUs received with the outstanding transaction id, handed on."""
    dropped: int = 0
    """ADUs received with another transaction id (stale or unknown), dropped."""
    strangers: int = 0
    """Modbus UDP: datagrams from an address other than the server's, dropped."""
    refused: int = 0
    """Modbus UDP: datagrams that were not exactly one well-formed ADU, dropped."""


class ModbusTcpStream(anyio.abc.ByteStream):
    """RTU frames over Modbus TCP on `stream` (see the module docstring).

    `send()` takes one whole RTU frame (unit, PDU, CRC) per call; `receive()` returns one
    RTU frame per call. `counters` are shared with other streams to the same server, or new.
    """

    def __init__(
        self, stream: anyio.abc.ByteStream, counters: ModbusTcpCounters | None = None
    ) -> None:
        self.stream = stream
        self.counters = counters if counters is not None else ModbusTcpCounters()
        """Requests, replies and dropped ADUs (see
        [`ModbusTcpCounters`][aiortu.transport.ModbusTcpCounters])."""
        self._decoder = AduDecoder()
        self._ready: deque[bytes] = deque()
        self._outstanding = NONE_OUTSTANDING

    @property
    def whole_frames(self) -> bool:
        """True: each `receive()` returns exactly one RTU frame."""
        return True

    @property
    def unit_ids(self) -> UnitIds:
        """Any byte of the MBAP header, each a unit whose reply is awaited."""
        return MBAP_UNIT_IDS

    @property
    def extra_attributes(self) -> Any:
        return self.stream.extra_attributes

    async def send(self, item: bytes) -> None:
        """Send the RTU frame `item` as one ADU with the next transaction id."""
        transaction_id, adu = request_adu(self.counters, item)
        # Outstanding before the write: a fast reply may be read while send() yields.
        self._outstanding = transaction_id
        self._ready.clear()  # a new request: nothing that came before answers it
        await self.stream.send(adu)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """The next reply to the request outstanding, as an RTU frame (`max_bytes` is ignored:
        a frame is never split)."""
        # Always a checkpoint, so that a caller's expired deadline takes effect before the
        # next frame is handed over.
        await anyio.lowlevel.checkpoint()
        while not self._ready:
            data = await self.stream.receive()
            try:
                adus = self._decoder.feed(data)
            except MalformedHeader as error:
                _log.warning("closing the Modbus TCP connection: %s", error)
                await self.stream.aclose()
                raise anyio.BrokenResourceError(str(error)) from error
            for adu in adus:
                frame = reply_frame(self.counters, self._outstanding, adu)
                if frame is not None:
                    self._outstanding = NONE_OUTSTANDING  # one reply per request
                    self._ready.append(frame)
        return self._ready.popleft()

    async def send_eof(self) -> None:
        await self.stream.send_eof()

    async def aclose(self) -> None:
        await self.stream.aclose()
