"""The pushed MBAP streams' repeats against the general route, byte for byte: a master's
pushed Modbus TCP (and TLS) stream and its pushed Modbus UDP stream are fed seeded scripts of
replies (the same reply again, other values, stale and unknown transaction ids, replies split
and joined, malformed headers and datagrams), and every frame handed on, every counter and the
stream's end must be what the decoder and `reply_frame` give for the same bytes; every request
ADU what `request_adu` gives."""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable

import pytest

from aiortu.core.mbap import AduDecoder, MalformedHeader, encode_adu
from aiortu.errors import FrameError
from aiortu.transport import (
    ModbusTcpCounters,
    PushConnectionStream,
    PushDatagramStream,
    check_datagram,
)
from aiortu.transport._mbap_stream import NONE_OUTSTANDING, reply_frame, request_adu

PEER = ("127.0.0.1", 502)
REQUESTS = (bytes.fromhex("01 03 0000 0002 C40B"), bytes.fromhex("11 03 006B 0003 7687"))
"""Two requests, so that a script sends the same one again and another one."""


class GeneralRoute:
    """What the general route does with the same bytes: the stream decoder, then
    `reply_frame` against the transaction outstanding (one reply per request)."""

    def __init__(self, datagrams: bool) -> None:
        self.datagrams = datagrams
        self.counters = ModbusTcpCounters()
        self.decoder = AduDecoder()
        self.outstanding = NONE_OUTSTANDING
        self.frames: list[bytes] = []
        self.ended = False

    def request(self, item: bytes) -> bytes:
        self.outstanding, adu = request_adu(self.counters, item)
        return adu

    def feed(self, data: bytes) -> None:
        if self.datagrams:
            try:
                adus = [check_datagram(data)]
            except FrameError:
                self.counters.refused += 1
                return
        else:
            try:
                adus = self.decoder.feed(data)
            except MalformedHeader:
                self.ended = True
                return
        for adu in adus:
            frame = reply_frame(self.counters, self.outstanding, adu)
            if frame is not None:
                self.outstanding = NONE_OUTSTANDING
                self.frames.append(frame)


def _reply(rng: random.Random, transaction_id: int, unit: int) -> bytes:
    """A register read's reply: mostly the same values, sometimes others."""
    values = rng.choice((b"\x00\x2a\x00\x07", b"\x00\x2a\x00\x07", b"\x12\x34\x56\x78"))
    return encode_adu(transaction_id, unit, bytes((3, len(values))) + values)


def _chunks(rng: random.Random, transaction_id: int, unit: int, datagrams: bool) -> list[bytes]:
    """What a server sends after a request: the reply, with one turn of the script."""
    reply = _reply(rng, transaction_id, unit)
    stale = _reply(rng, (transaction_id - 1) & 0xFFFF, unit)
    unknown = _reply(rng, 0xBEEF, unit)
    turn = rng.randrange(10)
    if turn == 0:
        return []  # lost
    if turn == 1:
        return [stale, reply]  # a late reply first, alone
    if turn == 2:
        return [unknown, reply, reply]  # an id never sent; a duplicate
    if turn == 3 and not datagrams:
        cut = rng.randrange(1, len(reply))
        return [reply[:cut], reply[cut:]]  # split
    if turn == 4 and not datagrams:
        return [stale + reply]  # joined
    if turn == 5 and not datagrams:
        cut = rng.randrange(1, len(reply))
        return [stale[:cut], stale[cut:] + reply]  # the next chunk ends the one before
    if turn == 7 and not datagrams:
        return [reply + unknown[:3], unknown[3:]]  # the reply and the start of the next ADU
    if turn == 8 and not datagrams:
        return [unknown[: rng.randrange(1, 8)], reply]  # the reply while an ADU is under way
    if turn == 6 and rng.random() < 0.3:
        broken = bytes((transaction_id >> 8, transaction_id & 0xFF, 0, 7)) + reply[4:]
        return [broken, reply]  # a malformed header (protocol 7), then the reply again
    return [reply]


def _run(seed: int, datagrams: bool) -> None:
    rng = random.Random(seed)
    general = GeneralRoute(datagrams)
    frames: list[bytes] = []
    stream: PushConnectionStream | PushDatagramStream
    feed: Callable[[bytes], None]
    if datagrams:
        udp = PushDatagramStream(PEER, ModbusTcpCounters(), "udp://test", check_datagram)
        feed, stream = (lambda data: udp.datagram(data, PEER)), udp
    else:
        stream = PushConnectionStream(ModbusTcpCounters(), "tcp://test")
        feed = stream.data
    stream.set_receiver(frames.append)
    for step in range(40):
        item = rng.choice(REQUESTS)
        adu = stream.request(item)
        assert adu == general.request(item), f"seed {seed}, step {step}: the request's ADU"
        for chunk in _chunks(rng, (adu[0] << 8) | adu[1], item[0], datagrams):
            feed(chunk)
            general.feed(chunk)
            assert frames == general.frames, f"seed {seed}, step {step}: the frames handed on"
    assert dataclasses.asdict(stream.counters) == dataclasses.asdict(general.counters), (
        f"seed {seed}: the counters"
    )
    assert (stream._error is not None) == general.ended, f"seed {seed}: how the stream ended"


@pytest.mark.parametrize("seed", range(200))
def test_the_pushed_tcp_stream_gives_what_the_general_route_gives(seed: int) -> None:
    _run(seed, datagrams=False)


@pytest.mark.parametrize("seed", range(100))
def test_the_pushed_udp_stream_gives_what_the_general_route_gives(seed: int) -> None:
    _run(seed, datagrams=True)


def test_a_poll_reuses_the_reply_it_has_seen() -> None:
    """The same reply again (with the next id) is handed on with the RTU frame made the first
    time, not one made again; a chunk that is not one ADU alone is not remembered."""
    stream = PushConnectionStream(ModbusTcpCounters(), "tcp://test")
    frames: list[bytes] = []
    stream.set_receiver(frames.append)
    for transaction_id in range(3):
        stream.request(REQUESTS[0])
        stream.data(encode_adu(transaction_id, 1, bytes.fromhex("03 04 002A 0007")))
    assert frames[0] == bytes.fromhex("01 03 04 002A 0007") + frames[0][-2:]
    assert frames[1] is frames[0]
    assert frames[2] is frames[0]
    stream.request(REQUESTS[0])
    reply = encode_adu(3, 1, bytes.fromhex("03 04 0000 0001"))
    stream.data(reply[:4])
    stream.data(reply[4:])
    stream.request(REQUESTS[0])
    stream.data(encode_adu(4, 1, bytes.fromhex("03 04 0000 0001")))
    assert frames[4] == frames[3]
    assert frames[4] is not frames[3]
    assert stream.counters.replies == 5
