"""The RTU receiver: its transition table, framing, resync, roles, timing and bounds."""

from __future__ import annotations

import itertools
import random
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from aiortu.core.pdu import (
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    WriteMultipleRegistersRequest,
)
from aiortu.core.rtu import (
    MAX_FRAME_LENGTH,
    MIN_FRAME_LENGTH,
    TOLERANT_FRAME_SILENCE,
    DiscardReason,
    FrameDiscarded,
    FrameReceived,
    Receiver,
    ReceiverError,
    ReceiverEvent,
    ReceiverState,
    Role,
    TimingMode,
    crc16,
    encode_frame,
    expected_request_length,
    expected_response_length,
)
from aiortu.core.rtu._receiver import TRANSITIONS, ReceiverOutput
from aiortu.core.serial import LineSettings
from tests.core.frame_strategies import Sample, customs, has_accidental_prefix, requests, responses

S = ReceiverState
E = ReceiverEvent
H = bytes.fromhex
SETTINGS = [LineSettings(9600), LineSettings(19200), LineSettings(115200)]
OWN_UNIT = 3


# -- a model of the wire -------------------------------------------------------------------


@dataclass
class Wire:
    """Bytes with the times they finish arriving, and the chunks a driver would hand over.

    Inside a chunk the characters are back to back, which is what the receiver assumes, so
    the times it reports must be exact.
    """

    char_time: float
    now: float = 1.0
    data: bytearray = field(default_factory=bytearray)
    times: list[float] = field(default_factory=list)
    cuts: set[int] = field(default_factory=set)
    silences: set[int] = field(default_factory=set)
    """Positions followed by a silence that ends a frame."""

    def add(self, data: bytes, gap: float = 0.0) -> tuple[int, int]:
        """Append *data* after *gap* seconds of quiet; return its (start, end) positions."""
        start = len(self.data)
        if gap and start:
            self.cuts.add(start)
        for byte in data:
            self.now += self.char_time + (gap if len(self.data) == start else 0.0)
            self.data.append(byte)
            self.times.append(self.now)
        return start, len(self.data)

    def silence(self, seconds: float) -> None:
        self.now += seconds
        if self.data:
            self.cuts.add(len(self.data))
            self.silences.add(len(self.data))

    def chunks(self, extra_cuts: Iterable[int] = ()) -> list[tuple[bytes, float]]:
        """The chunks between cuts, each with the arrival time of its last byte."""
        cuts = sorted({0, len(self.data), *self.cuts, *extra_cuts})
        return [
            (bytes(self.data[a:b]), self.times[b - 1]) for a, b in itertools.pairwise(cuts) if b > a
        ]


def run(
    receiver: Receiver, chunks: Sequence[tuple[bytes, float]], end: float | None = None
) -> list[ReceiverOutput]:
    """Feed *chunks*, waking the receiver at its deadlines as a driver does, then let it expire.

    The driver wakes the receiver only at deadlines before the next chunk began arriving:
    one that falls while a chunk is on its way cannot be seen by anyone.
    """
    out: list[ReceiverOutput] = []
    for data, when in chunks:
        deadline = receiver.next_deadline()
        if deadline is not None and deadline < when - len(data) * receiver.char_time:
            out += receiver.expire(deadline)
        out += receiver.feed(data, when)
    out += receiver.expire(end if end is not None else (chunks[-1][1] if chunks else 0.0) + 1.0)
    return out


def received(outputs: Iterable[ReceiverOutput]) -> list[FrameReceived]:
    return [output for output in outputs if isinstance(output, FrameReceived)]


def discarded(outputs: Iterable[ReceiverOutput]) -> list[FrameDiscarded]:
    return [output for output in outputs if isinstance(output, FrameDiscarded)]


def make(role: Role, settings: LineSettings, timing: TimingMode, **kwargs: object) -> Receiver:
    units = (OWN_UNIT,) if role is Role.SLAVE else ()
    return Receiver(settings, role=role, units=units, timing=timing, **kwargs)  # type: ignore[arg-type]


def frames_for(role: Role) -> st.SearchStrategy[Sample]:
    """The frames a receiver in *role* is meant to receive."""
    if role is Role.MASTER:
        return st.one_of(responses(), customs(reply=True))
    if role is Role.SLAVE:
        own = st.just(OWN_UNIT)
        return st.one_of(requests(own), customs(own))
    return st.one_of(requests(), responses(), customs())


def predictable_frames_for(role: Role) -> st.SearchStrategy[Sample]:
    """The frames of :func:`frames_for` whose layout gives their length. Custom function
    codes never do: leaving them out here keeps hypothesis from rejecting half its draws."""
    if role is Role.MASTER:
        frames = responses()
    elif role is Role.SLAVE:
        frames = requests(st.just(OWN_UNIT))
    else:
        frames = st.one_of(requests(), responses())
    return frames.filter(lambda s: s.predictable)


def guesses(data: bytes) -> set[int]:
    """Every length either predictor gives for a frame starting with *data*."""
    return {expected_request_length(data), expected_response_length(data)}


def false_frames(
    stream: bytes, sent: set[tuple[int, int]], boundaries: Iterable[int]
) -> set[bytes]:
    """Slices of *stream* with a good CRC that the receiver could take for frames, other than the
    frames that were sent (*sent* holds their (start, end) positions).

    The receiver only ever checks a CRC at a predicted length or at the end of a buffer
    closed by silence, so only those slices are looked at. Random bytes give one in 65536.
    """
    ends = sorted(set(boundaries) | {len(stream)})
    found = set()
    for start in range(len(stream) - MIN_FRAME_LENGTH + 1):
        window = stream[start : start + MAX_FRAME_LENGTH]
        lengths = {g for g in guesses(window) if g >= MIN_FRAME_LENGTH}
        lengths |= {
            end - start for end in ends if MIN_FRAME_LENGTH <= end - start <= MAX_FRAME_LENGTH
        }
        for length in lengths:
            end = start + length
            if end <= len(stream) and (start, end) not in sent and crc16(stream[start:end]) == 0:
                found.add(stream[start:end])
    return found


def accidental(sample: Sample) -> bool:
    """Whether a shorter predicted length of *sample* happens to have a good CRC."""
    return has_accidental_prefix(sample.frame)


# -- the transition table ------------------------------------------------------------------


class Spy:
    """Records which action each fired transition ran, in which state; can hold an action back."""

    def __init__(self, receiver: Receiver) -> None:
        self.calls: list[tuple[tuple[S, E], S, str]] = []
        self.hold: set[tuple[S, E]] = set()
        for key, (target, action) in list(receiver._actions.items()):
            receiver._actions[key] = (target, self._wrap(receiver, key, action))

    def _wrap(
        self, receiver: Receiver, key: tuple[S, E], action: Callable[..., int]
    ) -> Callable[..., int]:
        def wrapped(data: bytes, position: int) -> int:
            self.calls.append((key, receiver.state, action.__name__))
            if key in self.hold:
                return position
            return action(data, position)

        return wrapped


def _reach(state: S, how: int, settings: LineSettings) -> tuple[Receiver, Spy]:
    """A receiver brought to *state* by real input; *how* picks one of several ways."""
    strict = TimingMode.STRICT
    c = settings.char_time
    receiver = Receiver(
        settings,
        role=Role.MONITOR,
        timing=strict,
        now=0.0 if state is S.INIT and how == 0 else None,
    )
    spy = Spy(receiver)
    request = H("11 03 00 6B 00 03 76 87")
    if state is S.INIT and how == 1:
        receiver.feed(b"\x11\x03", 1.0)
        receiver.feed(b"\x00", 1.0 + c + 2 * settings.t1_5)  # late: the frame is broken
    elif state is S.INIT and how == 2:
        receiver.feed(b"\x11\x41" + bytes(300), 1.0)  # overflow
    elif state is S.IDLE and how == 1:
        receiver.feed(request, 1.0)
    elif state is S.IDLE and how == 2:
        receiver.feed(b"\x11\x41\x00", 1.0)
        receiver.expire(2.0)
    elif state is S.START:
        receiver.feed(request[:1], 1.0)
    elif state in (S.DATABUF, S.RESPONSE):
        receiver.feed(request[: 2 + how], 1.0)
        if state is S.RESPONSE:
            spy.hold.add((S.DATABUF, E.SILENCE))
            receiver.expire(2.0)
    assert receiver.state is state
    spy.calls.clear()
    spy.hold.clear()
    return receiver, spy


@settings(max_examples=200)
@given(
    state=st.sampled_from(S),
    event=st.sampled_from(E),
    how=st.integers(0, 2),
    chunk=st.binary(min_size=1, max_size=8),
    baud=st.sampled_from(SETTINGS),
)
def test_every_state_event_pair(
    state: S, event: E, how: int, chunk: bytes, baud: LineSettings
) -> None:
    receiver, spy = _reach(state, how, baud)
    data = chunk if event in (E.CHARS, E.LATE_CHARS) else b""
    if (state, event) not in TRANSITIONS:
        with pytest.raises(ReceiverError, match=event.name):
            receiver._fire(event, data, 0, 3.0)
        assert receiver.state is state
        assert not spy.calls
        return
    target, action = TRANSITIONS[state, event]
    receiver._fire(event, data, 0, 3.0)
    # The first action run is the table's, in the table's next state.
    assert spy.calls[0] == ((state, event), target, f"_{action}")


def test_table_shape() -> None:
    pairs = set(TRANSITIONS)
    states = {s for s, _ in pairs}
    assert states == set(S)
    # RESPONSE is transient: it accepts only CHECKED, which leads back to IDLE.
    assert {e for s, e in pairs if s is S.RESPONSE} == {E.CHECKED}
    assert TRANSITIONS[S.RESPONSE, E.CHECKED][0] is S.IDLE
    # Only a frame being stored can complete, and only a closed one can be checked.
    assert {s for s, e in pairs if e is E.COMPLETE} == {S.DATABUF}
    assert {s for s, e in pairs if e is E.CHECKED} == {S.RESPONSE}
    # Only states that gather bytes without a predicted end can overflow.
    assert {s for s, e in pairs if e is E.OVERFLOW} == {S.INIT, S.DATABUF}
    # Bytes and silence can come in every waiting state.
    for s in set(S) - {S.RESPONSE}:
        assert {(s, E.CHARS), (s, E.LATE_CHARS), (s, E.SILENCE)} <= pairs
    # Every action names a method, and every target is a state.
    receiver = Receiver()
    for target, action in TRANSITIONS.values():
        assert callable(getattr(receiver, f"_{action}"))
        assert target in S


def test_every_state_is_reachable_and_can_get_back_to_idle() -> None:
    def closure(start: S, edges: dict[S, set[S]]) -> set[S]:
        seen, todo = {start}, [start]
        while todo:
            for nxt in edges.get(todo.pop(), set()):
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return seen

    forward: dict[S, set[S]] = {}
    backward: dict[S, set[S]] = {}
    for (source, _), (target, _) in TRANSITIONS.items():
        forward.setdefault(source, set()).add(target)
        backward.setdefault(target, set()).add(source)
    assert closure(S.INIT, forward) == set(S)
    assert closure(S.IDLE, backward) == set(S)


def test_the_two_initial_states() -> None:
    assert Receiver().state is S.IDLE
    assert Receiver().next_deadline() is None
    receiver = Receiver(LineSettings(9600), timing="strict", now=5.0)
    assert receiver.state is S.INIT
    assert receiver.next_deadline() == 5.0 + LineSettings(9600).t3_5


# -- every valid frame is received ---------------------------------------------------------


ROLES = [Role.MASTER, Role.SLAVE, Role.MONITOR]


@pytest.mark.parametrize("role", ROLES)
@pytest.mark.parametrize("timing", list(TimingMode))
@settings(max_examples=40)
@given(data=st.data())
def test_every_frame_is_received_once_in_order(
    role: Role, timing: TimingMode, data: st.DataObject
) -> None:
    line = data.draw(st.sampled_from(SETTINGS))
    samples = data.draw(st.lists(frames_for(role), min_size=1, max_size=4))
    assume(not any(accidental(sample) for sample in samples))
    receiver = make(role, line, timing)
    wire = Wire(line.char_time)
    spans = []
    rng = random.Random(data.draw(st.integers(0, 2**32)))
    for sample in samples:
        # Inside a frame, chunks come with gaps shorter than t1.5.
        start, _ = wire.add(sample.frame[:1])
        position = 1
        while position < len(sample.frame):
            size = rng.randint(1, len(sample.frame) - position)
            wire.add(sample.frame[position : position + size], gap=rng.uniform(0, 0.95 * line.t1_5))
            position += size
        spans.append((wire.times[start], wire.now))
        wire.silence(receiver.frame_silence * 1.01)
    mode = data.draw(st.sampled_from(["whole", "bytes", "chunks"]))
    extra = {
        "whole": (),
        "bytes": range(len(wire.data)),
        "chunks": rng.sample(range(len(wire.data)), k=min(len(wire.data), 10)),
    }[mode]
    outputs = run(receiver, wire.chunks(extra))
    assert not discarded(outputs)
    got = received(outputs)
    assert [frame.frame for frame in got] == [sample.frame for sample in samples]
    for frame, (start, end) in zip(got, spans, strict=True):
        assert frame.start == pytest.approx(start, abs=1e-9)
        assert frame.end == pytest.approx(end, abs=1e-9)


@pytest.mark.parametrize("role", ROLES)
@settings(max_examples=40)
@given(data=st.data())
def test_predictable_frames_complete_without_silence(role: Role, data: st.DataObject) -> None:
    """Length-aware: back-to-back frames of known length come out of feed() alone."""
    samples = data.draw(st.lists(predictable_frames_for(role), min_size=1, max_size=4))
    assume(not any(accidental(sample) for sample in samples))
    receiver = make(role, LineSettings(19200), TimingMode.TOLERANT)
    stream = b"".join(sample.frame for sample in samples)
    split = data.draw(st.sampled_from([1, 7, len(stream)]))
    outputs: list[ReceiverOutput] = []
    for index in range(0, len(stream), split):
        outputs += receiver.feed(stream[index : index + split], 1.0 + index * receiver.char_time)
    assert [frame.frame for frame in received(outputs)] == [sample.frame for sample in samples]
    assert receiver.state is S.IDLE
    assert receiver.next_deadline() is None


@pytest.mark.parametrize("role", ROLES)
@settings(max_examples=25)
@given(data=st.data())
def test_first_frame_after_the_initial_silence(role: Role, data: st.DataObject) -> None:
    """Started mid-frame: the tail already on the line is noise; the next frame is received."""
    line = LineSettings(19200)
    tail_of = data.draw(frames_for(role))
    sample = data.draw(frames_for(role))
    tail = tail_of.frame[data.draw(st.integers(1, len(tail_of.frame) - 1)) :]
    assume(not accidental(sample))
    receiver = make(role, line, TimingMode.STRICT, now=1.0)
    wire = Wire(line.char_time, now=1.0)
    wire.add(tail)
    wire.silence(line.t3_5 * 1.01)
    start, end = wire.add(sample.frame)
    assume(not false_frames(bytes(wire.data), {(start, end)}, wire.silences))
    outputs = run(receiver, wire.chunks())
    assert [frame.frame for frame in received(outputs)] == [sample.frame]
    assert [(d.data, d.reason) for d in discarded(outputs)] == [(tail, DiscardReason.NOISE)]


def test_initial_silence_counts_from_now() -> None:
    line = LineSettings(9600)
    frame = H("11 03 00 6B 00 03 76 87")
    receiver = Receiver(line, role=Role.MONITOR, timing="strict", now=10.0)
    # The first byte starts just after t3.5 from now: the silence is complete.
    out = receiver.feed(frame, 10.0 + line.t3_5 + 1e-9 + len(frame) * line.char_time)
    assert received(out)[0].frame == frame


# -- garbage -------------------------------------------------------------------------------


@dataclass
class Item:
    data: bytes
    frame: Sample | None
    silence_before: bool


@pytest.mark.parametrize("role", ROLES)
@pytest.mark.parametrize("timing", list(TimingMode))
@settings(max_examples=60)
@given(data=st.data())
def test_garbage_never_makes_a_frame_and_good_frames_survive(
    role: Role, timing: TimingMode, data: st.DataObject
) -> None:
    """Frames and garbage, back to back or separated by the silence that ends a frame.

    Which frames must survive: the receiver is in step at the start of every group of
    items between two silences, and stays in step over frames of predictable length
    (they complete at once); garbage or a frame whose length only silence tells puts it
    out of step until the next silence.

    - A frame of predictable length always survives: in step it completes at once; out of
      step the silence (or an overflow) makes the receiver search the buffer for it, so
      garbage right before it, or after it, costs nothing.
    - A frame whose length only silence tells survives when the receiver is in step at its
      start and a silence follows it.
    """
    line = data.draw(st.sampled_from(SETTINGS))
    garbage = st.binary(min_size=1, max_size=30).map(lambda g: Item(g, None, False))
    frame = frames_for(role).map(lambda s: Item(s.frame, s, False))
    items = data.draw(st.lists(st.one_of(garbage, frame), min_size=1, max_size=6))
    items = [Item(i.data, i.frame, data.draw(st.booleans())) for i in items]
    receiver = make(role, line, timing)
    wire = Wire(line.char_time)
    sent: dict[tuple[int, int], bytes] = {}
    survivors: list[tuple[int, int]] = []
    in_step = True
    for index, item in enumerate(items):
        if item.silence_before and index:
            wire.silence(receiver.frame_silence * 1.01)
            in_step = True
        span = wire.add(item.data)
        if item.frame is None:
            in_step = False
            continue
        sent[span] = item.data
        silence_after = index + 1 == len(items) or items[index + 1].silence_before
        if item.frame.predictable or (in_step and silence_after):
            survivors.append(span)
        in_step = in_step and item.frame.predictable
    stream = bytes(wire.data)
    assume(not false_frames(stream, set(sent), wire.silences))
    split = data.draw(st.sampled_from([0, 1, 5]))
    extra = range(0, len(stream), split) if split else ()
    outputs = run(receiver, wire.chunks(extra))
    got = received(outputs)
    # Never a false frame: each one received is one sent, in the order sent.
    order = []
    for frame in got:
        spans = [span for span, sent_frame in sent.items() if sent_frame == frame.frame]
        assert spans, f"false frame {frame.frame.hex(' ')}"
        order.append(min(spans, key=lambda span: abs(wire.times[span[0]] - frame.start)))
    assert order == sorted(set(order))
    # The frames that must survive did, with the times their bytes arrived.
    assert set(survivors) <= set(order)
    for frame, span in zip(got, order, strict=True):
        assert frame.start == pytest.approx(wire.times[span[0]], abs=1e-9)
        assert frame.end == pytest.approx(wire.times[span[1] - 1], abs=1e-9)
    # Every byte comes out once, in order, in a frame or a discard, timed as it arrived.
    outputs_bytes = b"".join(o.frame if isinstance(o, FrameReceived) else o.data for o in outputs)
    assert outputs_bytes == stream
    position = 0
    for output in outputs:
        size = len(output.frame if isinstance(output, FrameReceived) else output.data)
        assert output.start == pytest.approx(wire.times[position], abs=1e-9)
        assert output.end == pytest.approx(wire.times[position + size - 1], abs=1e-9)
        position += size


def test_garbage_right_before_a_frame_then_silence() -> None:
    line = LineSettings(19200)
    reply = H("11 03 06 AE 41 56 52 43 40 49 AD")
    request = encode_frame(OWN_UNIT, H("03 00 00 00 01"))
    for role in ROLES:
        for frame in (reply, request):
            receiver = Receiver(line, role=role, units=(OWN_UNIT,))
            out = receiver.feed(b"\x99\x17\x42" + frame, 1.0)
            out += receiver.expire(2.0)
            if role is Role.MASTER and frame is request:
                continue  # not a reply: a master has no use for it
            if role is Role.SLAVE and frame is reply:
                # Inside garbage a slave looks for its own requests only: another unit's
                # frame glued to garbage goes with it.
                assert not received(out)
                assert [(d.data, d.reason) for d in discarded(out)] == [
                    (b"\x99\x17\x42" + frame, DiscardReason.CRC)
                ]
                continue
            assert [r.frame for r in received(out)] == [frame]
            assert [(d.data, d.reason) for d in discarded(out)] == [
                (b"\x99\x17\x42", DiscardReason.CRC)
            ]


@pytest.mark.parametrize("seed", range(12))
def test_request_inside_a_continuous_flood_of_garbage(seed: int) -> None:
    """A request to the slave's unit glued to random garbage on both sides, no silence.

    The flood overflows the buffer again and again; the request, at a random offset and
    cut by random chunk boundaries, must still be received, and nothing else: a frame
    received is the request, never a piece of garbage with a good CRC at a length the
    receiver predicted (those are left out of the draw, as they are real frames).
    """
    rng = random.Random(seed)
    line = LineSettings(19200, parity="N", stopbits=2)
    request = encode_frame(
        1, ReadHoldingRegistersRequest(rng.randrange(0x10000 - 125), 10).encode()
    )
    for _ in range(100):
        before = rng.randbytes(rng.randrange(4000, 12000))
        after = rng.randbytes(rng.randrange(300, 3000))
        stream = before + request + after
        receiver = Receiver(line, role=Role.SLAVE, units={1})
        # Any offset where a request to unit 1 or a broadcast with a good CRC starts, other
        # than the one sent, would be a true frame; the draw avoids them.
        probe = Receiver(line, role=Role.SLAVE, units={1})
        probe.feed(before, 1.0)
        probe.feed(after, 2.0)
        if not any(isinstance(o, FrameReceived) for o in probe.expire(3.0)):
            break
    else:
        pytest.fail("no draw without a true frame in the garbage")
    wire = Wire(line.char_time)
    wire.add(stream)
    cuts: set[int] = set()
    position = 0
    while position < len(stream):
        position += rng.choice((1, 2, 7, rng.randrange(1, 600)))
        cuts.add(position)
    outputs: list[ReceiverOutput] = []
    for data, when in wire.chunks(cut for cut in cuts if cut < len(stream)):
        outputs += receiver.feed(data, when)
    # Found while the flood goes on, before any silence ends it.
    assert [r.frame for r in received(outputs)] == [request]
    (got,) = received(outputs)
    assert got.start == pytest.approx(wire.times[len(before)], abs=1e-9)
    assert got.end == pytest.approx(wire.times[len(before) + len(request) - 1], abs=1e-9)
    outputs += receiver.expire(wire.times[-1] + 1.0)
    assert [r.frame for r in received(outputs)] == [request]
    assert b"".join(o.frame if isinstance(o, FrameReceived) else o.data for o in outputs) == stream
    assert {d.reason for d in discarded(outputs)} <= {DiscardReason.OVERFLOW, DiscardReason.NOISE}


def test_device_identification_reply_is_found_after_garbage() -> None:
    # The reply's length depends on every object's length byte, far beyond its first bytes.
    pdu = H("2B 0E 01 81 00 00 03") + b"\x00\x0avendorname" + b"\x01\x04prod" + b"\x02\x04v1.0"
    frame = encode_frame(5, pdu)
    for role in (Role.MASTER, Role.MONITOR):
        receiver = Receiver(role=role)
        out = receiver.feed(b"\x99\x17" + frame, 1.0) + receiver.expire(2.0)
        assert [r.frame for r in received(out)] == [frame]


def test_overflow_salvage_keeps_the_times_of_the_bytes_it_keeps() -> None:
    line = LineSettings(19200)
    c = line.char_time
    frame = H("11 03 06 AE 41 56 52 43 40 49 AD")
    receiver = Receiver(line, role=Role.MASTER)
    # 300 bytes that start like an unknown function code, then a frame, back to back.
    noise = b"\x11\x41" + bytes(298)
    stream = noise + frame
    out = receiver.feed(stream, 1.0) + receiver.expire(2.0)
    (got,) = received(out)
    first = 1.0 - (len(stream) - 1) * c
    assert got.start == pytest.approx(first + len(noise) * c)
    assert got.end == pytest.approx(1.0)
    assert DiscardReason.OVERFLOW in {d.reason for d in discarded(out)}


# -- a slave on a multi-drop bus -----------------------------------------------------------


EMBEDDED = encode_frame(OWN_UNIT, H("03 00 00 00 01"))  # 03 03 00 00 00 01 85 E8
assert H("03 03 00 00 00 01 85 E8") == EMBEDDED


@st.composite
def _pairs(draw: st.DrawFn) -> list[bytes]:
    """A request/reply pair for another unit, often carrying a whole request to our unit."""
    unit = draw(st.integers(1, 247).filter(lambda u: u != OWN_UNIT))
    kind = draw(st.sampled_from(["embed reply", "embed request", "any"]))
    if kind == "any":
        request = draw(requests(st.just(unit)).filter(lambda s: s.predictable))
        reply = draw(responses(st.just(unit)).filter(lambda s: s.predictable))
        return [request.frame, reply.frame]
    before = draw(st.binary(max_size=20))
    after = draw(st.binary(max_size=20))
    payload = before + EMBEDDED + after + (b"\x00" if (len(before) + len(after)) % 2 else b"")
    values = tuple(int.from_bytes(payload[i : i + 2], "big") for i in range(0, len(payload), 2))
    if kind == "embed reply":
        request = ReadHoldingRegistersRequest(0, len(values)).encode()
        return [
            encode_frame(unit, request),
            encode_frame(unit, ReadHoldingRegistersResponse(values).encode()),
        ]
    request = WriteMultipleRegistersRequest(0, values).encode()
    return [
        encode_frame(unit, request),
        encode_frame(unit, H("10 00 00") + len(values).to_bytes(2, "big")),
    ]


@pytest.mark.parametrize("timing", list(TimingMode))
@settings(max_examples=60)
@given(pairs=st.lists(_pairs(), min_size=1, max_size=5), data=st.data())
def test_slave_skips_other_units_traffic(
    timing: TimingMode, pairs: list[list[bytes]], data: st.DataObject
) -> None:
    line = LineSettings(19200)
    frames = [frame for pair in pairs for frame in pair]
    samples = [Sample(frame, index % 2 == 1, True) for index, frame in enumerate(frames)]
    # A reply whose first 8 bytes happen to make a request with a good CRC cannot be told
    # from one by its bytes alone; leave that one-in-65536 case out.
    assume(not any(accidental(sample) for sample in samples))
    receiver = Receiver(line, role=Role.SLAVE, units={OWN_UNIT}, timing=timing)
    wire = Wire(line.char_time)
    for frame in frames:
        wire.add(frame)
        wire.silence(line.t3_5 * 1.01)  # the spec's gap: shorter than the tolerant bound
    split = data.draw(st.sampled_from([0, 1, 3]))
    extra = range(0, len(wire.data), split) if split else ()
    got = received(run(receiver, wire.chunks(extra)))
    assert all(frame.unit != OWN_UNIT for frame in got)
    assert [frame.frame for frame in got] == frames


def test_slave_takes_its_own_requests_and_broadcasts() -> None:
    own = encode_frame(OWN_UNIT, H("03 00 00 00 01"))
    broadcast = encode_frame(0, H("06 00 01 00 02"))
    receiver = Receiver(role=Role.SLAVE, units={OWN_UNIT})
    assert [r.frame for r in received(receiver.feed(own + broadcast, 1.0))] == [own, broadcast]


# -- strict and tolerant timing ------------------------------------------------------------


REQUEST = H("11 03 00 6B 00 03 76 87")


@pytest.mark.parametrize("line", SETTINGS, ids=str)
def test_strict_gap_longer_than_t1_5_discards(line: LineSettings) -> None:
    c = line.char_time
    receiver = Receiver(line, role=Role.SLAVE, units={0x11}, timing="strict")
    out = receiver.feed(REQUEST[:3], 1.0)
    later = 1.0 + line.t1_5 * 1.05 + 5 * c
    out += receiver.feed(REQUEST[3:], later)
    out += receiver.expire(later + 1.0)
    assert not received(out)
    assert discarded(out)[0].reason is DiscardReason.GAP
    assert discarded(out)[0].data == REQUEST[:3]
    assert discarded(out)[0].end == 1.0


@pytest.mark.parametrize("line", SETTINGS, ids=str)
@pytest.mark.parametrize("timing", list(TimingMode))
def test_gap_shorter_than_t1_5_is_part_of_the_frame(line: LineSettings, timing: TimingMode) -> None:
    receiver = Receiver(line, role=Role.SLAVE, units={0x11}, timing=timing)
    out = receiver.feed(REQUEST[:3], 1.0)
    out += receiver.feed(REQUEST[3:], 1.0 + line.t1_5 * 0.95 + 5 * line.char_time)
    assert [r.frame for r in received(out)] == [REQUEST]


@pytest.mark.parametrize("line", SETTINGS, ids=str)
def test_tolerant_mode_accepts_the_gapped_frame(line: LineSettings) -> None:
    receiver = Receiver(line, role=Role.SLAVE, units={0x11})
    assert receiver.frame_silence == max(line.t3_5, TOLERANT_FRAME_SILENCE)
    out = receiver.feed(REQUEST[:3], 1.0)
    # Longer than t1.5 and t3.5, shorter than the tolerant bound: a USB adapter's pause.
    out += receiver.feed(REQUEST[3:], 1.0 + 0.015 + 5 * line.char_time)
    (got,) = received(out)
    assert got.frame == REQUEST
    assert got.start == pytest.approx(1.0 - 2 * line.char_time)
    assert got.end == pytest.approx(1.0 + 0.015 + 5 * line.char_time)


@pytest.mark.parametrize(
    ("line", "char_time", "t1_5", "t3_5"),
    [
        (LineSettings(9600), 11 / 9600, 0.00171875, 0.0040104166666666),
        (LineSettings(115200), 11 / 115200, 750e-6, 1750e-6),
    ],
    ids=["9600", "115200"],
)
def test_exact_deadlines(line: LineSettings, char_time: float, t1_5: float, t3_5: float) -> None:
    assert line.char_time == pytest.approx(char_time, rel=1e-12)
    assert line.t1_5 == pytest.approx(t1_5, rel=1e-12)
    assert line.t3_5 == pytest.approx(t3_5, rel=1e-9)
    receiver = Receiver(line, role=Role.MONITOR, timing="strict")
    assert receiver.frame_silence == line.t3_5
    custom = encode_frame(0x11, H("41 01 02 03"))  # a user-defined code: only silence ends it
    last = 100.0
    assert receiver.feed(custom[:4], last - 3 * char_time) == []
    assert receiver.next_deadline() == last - 3 * char_time + line.t3_5
    assert receiver.feed(custom[4:], last) == []
    assert receiver.next_deadline() == pytest.approx(last + t3_5, abs=1e-12)
    deadline = receiver.next_deadline()
    assert deadline is not None
    assert receiver.expire(deadline - 1e-9) == []
    assert receiver.state is S.DATABUF
    (got,) = receiver.expire(deadline)
    assert isinstance(got, FrameReceived)
    assert got.frame == custom
    assert got.start == pytest.approx(last - (len(custom) - 1) * char_time, abs=1e-12)
    assert got.end == last
    assert receiver.state is S.IDLE
    assert receiver.next_deadline() is None


def test_silence_seen_by_feed_ends_the_frame_before_the_new_bytes() -> None:
    line = LineSettings(9600)
    custom = encode_frame(0x11, H("41 01 02 03"))
    receiver = Receiver(line, role=Role.MONITOR, timing="strict")
    receiver.feed(custom, 1.0)
    # The next byte starts just after t3.5 from the end of the last one.
    out = receiver.feed(REQUEST, 1.0 + line.t3_5 + 1e-9 + len(REQUEST) * line.char_time)
    assert [r.frame for r in received(out)] == [custom, REQUEST]


# -- overflow and memory -------------------------------------------------------------------


def test_overflow_is_discarded_and_memory_stays_bounded() -> None:
    line = LineSettings(115200)
    rng = random.Random(1234)
    receiver = Receiver(line, role=Role.MONITOR)
    now = 1.0
    outputs: list[ReceiverOutput] = []
    longest = 0
    total = 0
    while total < 100_000:
        size = rng.randint(1, 64)
        chunk = bytes(rng.randrange(256) for _ in range(size))
        now += size * line.char_time
        outputs += receiver.feed(chunk, now)
        longest = max(longest, len(receiver._buffer))
        total += size
    assert longest <= MAX_FRAME_LENGTH
    assert any(d.reason is DiscardReason.OVERFLOW for d in discarded(outputs))
    # Noise never ends in a frame here except by chance; a frame after silence is received.
    out = receiver.feed(REQUEST, now + 1.0)
    out += receiver.expire(now + 2.0)
    assert REQUEST in [r.frame for r in received(out)]


def test_overflow_without_boundary() -> None:
    receiver = Receiver(role=Role.MASTER)
    noise = b"\x11\x41" + bytes(400)
    out = receiver.feed(noise, 1.0)
    assert {d.reason for d in discarded(out)} == {DiscardReason.OVERFLOW}
    assert len(receiver._buffer) <= MAX_FRAME_LENGTH
    out += receiver.expire(2.0)
    assert not received(out)
    assert sum(len(d.data) for d in discarded(out)) == len(noise)
    reply = H("11 03 06 AE 41 56 52 43 40 49 AD")
    assert [r.frame for r in received(receiver.feed(reply, 3.0))] == [reply]


def test_reset_forgets_the_partial_frame() -> None:
    line = LineSettings(19200)
    receiver = Receiver(line, role=Role.MASTER)
    receiver.feed(b"\x11\x03\x06\xae", 1.0)
    receiver.reset(2.0)
    assert receiver.state is S.INIT
    # INIT waits t3.5, as the spec has it, even where frames end on a longer silence.
    assert receiver.frame_silence > line.t3_5
    assert receiver.next_deadline() == 2.0 + line.t3_5
    out = receiver.feed(H("11 03 06 AE 41 56 52 43 40 49 AD"), 3.0)
    assert [r.frame for r in received(out)] == [H("11 03 06 AE 41 56 52 43 40 49 AD")]


def test_init_ends_on_t3_5_of_a_busy_line() -> None:
    """A slave that starts listening on a line never quiet for the tolerant frame
    silence (other masters polling back to back) syncs on the first t3.5 gap: a request
    it heard while in INIT is handed on then, not when the line first rests 20 ms (by
    then its master has long given up, and the late reply confuses it)."""
    line = LineSettings(9600)
    receiver = Receiver(line, role=Role.SLAVE, units=[1], now=0.0)
    request = H("01 03 00 00 00 01 84 0A")
    gap = 2 * line.t3_5  # far shorter than the tolerant 20 ms
    assert not received(receiver.feed(request, 0.001))
    out = receiver.feed(b"\xff\x00", 0.001 + gap)
    assert [r.frame for r in received(out)] == [request]
    assert receiver.state is not S.INIT
    later = H("01 03 00 01 00 01 D5 CA")
    out = receiver.feed(later, 0.001 + 3 * gap) + receiver.expire(1.0)
    assert [r.frame for r in received(out)] == [later]


def test_bad_frame_silence_is_refused() -> None:
    with pytest.raises(ValueError, match="frame_silence"):
        Receiver(frame_silence=-1.0)


@pytest.mark.parametrize("timing", list(TimingMode))
@settings(max_examples=60)
@given(data=st.data())
def test_taking_an_expected_frame_is_what_feed_does_with_it(
    timing: TimingMode, data: st.DataObject
) -> None:
    """A chunk the caller expects (its length matched to a layout) is taken exactly when
    feed() would receive it whole, and leaves the receiver as feed() does."""
    # The caller's part: the length matches the layout the first bytes give.
    sample = data.draw(responses().filter(lambda s: s.predictable))
    assume(expected_response_length(sample.frame) == len(sample.frame))
    frame = sample.frame
    if data.draw(st.booleans()):  # a bit flipped: the CRC no longer checks
        position = data.draw(st.integers(0, len(frame) - 1))
        frame = frame[:position] + bytes([frame[position] ^ 1 << data.draw(st.integers(0, 7))])
        frame += sample.frame[position + 1 :]
    # A good frame seen before (the last reply to the same request) may be named as
    # checked; whatever the chunk, the answer must not change.
    checked = data.draw(st.sampled_from([None, sample.frame, frame]))
    if checked is not None and crc16(checked) != 0:
        checked = None  # only a frame whose CRC was found good is ever named
    by_feed = make(Role.MASTER, LineSettings(19200), timing, now=0.0)
    by_take = make(Role.MASTER, LineSettings(19200), timing, now=0.0)
    for receiver in (by_feed, by_take):
        receiver.expire(1.0)  # out of INIT
    outputs = by_feed.feed(frame, 2.0)
    taken = by_take.take_expected_frame(frame, 2.0, checked)
    fed_whole = [output.frame for output in received(outputs)] == [frame]
    assert taken is (crc16(frame) == 0)
    if taken:
        assert fed_whole
        assert by_take.state is by_feed.state is S.IDLE
        assert by_take.next_deadline() == by_feed.next_deadline()
        # The next frame finds both the same way.
        assert by_take.feed(sample.frame, 3.0) == by_feed.feed(sample.frame, 3.0)
    else:
        assert by_take.state is S.IDLE  # nothing changed: the chunk goes to feed()
        assert by_take.feed(frame, 2.0) == outputs


def test_a_chunk_equal_to_the_checked_frame_skips_the_crc(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    reply = H("0103020007") + crc16(H("0103020007")).to_bytes(2, "little")
    receiver = make(Role.MASTER, LineSettings(19200), TimingMode.TOLERANT, now=0.0)
    receiver.expire(1.0)
    computed: list[bytes] = []

    def counted_crc16(data: bytes) -> int:
        computed.append(data)
        return crc16(data)

    monkeypatch.setattr("aiortu.core.rtu._receiver.crc16", counted_crc16)
    assert receiver.take_expected_frame(bytes(reply), 2.0, checked=reply)
    assert computed == []
    other = H("0103020008") + crc16(H("0103020008")).to_bytes(2, "little")
    assert receiver.take_expected_frame(other, 3.0, checked=reply)
    assert computed == [other]


def test_an_expected_frame_is_refused_unless_the_receiver_is_idle() -> None:
    receiver = make(Role.MASTER, LineSettings(19200), TimingMode.TOLERANT, now=0.0)
    reply = H("0103020007") + crc16(H("0103020007")).to_bytes(2, "little")
    assert not receiver.take_expected_frame(reply, 0.001)  # still INIT
    receiver.expire(1.0)
    receiver.feed(reply[:3], 1.5)  # a frame under way
    assert not receiver.take_expected_frame(reply, 1.6)
    assert receiver.state is not S.IDLE
