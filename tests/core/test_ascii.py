"""Modbus ASCII in the core: the LRC, the frame, and the receiver's table, timing and bounds."""

from __future__ import annotations

import itertools
import random
import re
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.ascii import (
    ASCII_TRANSITIONS,
    MAX_ASCII_FRAME_LENGTH,
    AsciiDiscardReason,
    AsciiEvent,
    AsciiFrameDiscarded,
    AsciiFrameReceived,
    AsciiReceiver,
    AsciiReceiverOutput,
    AsciiState,
    check_ascii_body,
    decode_ascii_frame,
    encode_ascii_frame,
    lrc,
)
from aiortu.core.errors import FrameError, InvalidValue, LRCError
from aiortu.core.rtu import ReceiverError

READ = encode_ascii_frame(1, bytes.fromhex("03 00 00 00 01"))
pdus = st.binary(min_size=1, max_size=253)
units = st.integers(0, 255)


def _frames(outputs: list[AsciiReceiverOutput]) -> list[bytes]:
    return [out.frame for out in outputs if isinstance(out, AsciiFrameReceived)]


def _discards(outputs: list[AsciiReceiverOutput]) -> list[AsciiDiscardReason]:
    return [out.reason for out in outputs if isinstance(out, AsciiFrameDiscarded)]


def _one_sentence(message: str) -> None:
    assert message
    assert "\n" not in message
    assert "Traceback" not in message


# -- the LRC and the frame ------------------------------------------------------------


def test_the_spec_example_lrc() -> None:
    assert lrc(bytes.fromhex("01 03 00 00 00 01")) == 0xFB
    assert READ == b":010300000001FB\r\n"


@given(st.binary(max_size=300))
def test_the_lrc_makes_the_sum_zero(data: bytes) -> None:
    assert (sum(data) + lrc(data)) & 0xFF == 0


@given(units, pdus)
def test_encode_then_decode_round_trips_in_either_case(unit: int, pdu: bytes) -> None:
    frame = encode_ascii_frame(unit, pdu)
    assert len(frame) <= MAX_ASCII_FRAME_LENGTH
    assert re.fullmatch(rb":[0-9A-F]+\r\n", frame)
    for text in (frame, frame.lower()):
        decoded = decode_ascii_frame(text)
        assert (decoded.unit, decoded.pdu) == (unit, pdu)


def test_the_longest_frame_is_513_characters() -> None:
    frame = encode_ascii_frame(1, bytes(253))
    assert len(frame) == MAX_ASCII_FRAME_LENGTH
    assert decode_ascii_frame(frame).pdu == bytes(253)
    with pytest.raises(InvalidValue):
        encode_ascii_frame(1, bytes(254))
    with pytest.raises(InvalidValue):
        encode_ascii_frame(256, b"\x03")
    with pytest.raises(InvalidValue):
        encode_ascii_frame(1, b"\x03", delimiter=ord(":"))


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        (b":0103000000\r\n" + b"0", "ends with CR"),  # end missing
        (b"010300000001FB\r\n", "starts with ':'"),
        (b":010300000001F\r\n", "even number"),
        (b":0103000 0001FB\r\n", "hex digits only"),  # fromhex would skip the space
        (b":01030000+001FB\r\n", "hex digits only"),
        (b":0103000\xff0001FB\r\n", "hex digits only"),
        (b":01FE\r\n", "6..510"),
        (b":" + b"0" * 511 + b"\r\n", "at most 513"),
        (b":" + b"00" * 300 + b"\r\n", "at most 513"),
        (b":010300000001FB\n\r", "ends with CR"),
    ],
)
def test_malformed_frames_are_refused_in_one_sentence(frame: bytes, words: str) -> None:
    with pytest.raises(FrameError) as caught:
        decode_ascii_frame(frame)
    assert caught.value.reason == "ascii"
    assert words in str(caught.value)
    _one_sentence(str(caught.value))


def test_a_wrong_lrc_is_an_lrc_error() -> None:
    with pytest.raises(LRCError) as caught:
        decode_ascii_frame(b":010300000001FC\r\n")
    assert (caught.value.received, caught.value.computed) == (0xFC, 0xFB)
    assert caught.value.reason == "lrc"
    _one_sentence(str(caught.value))


@given(st.binary(max_size=600))
def test_decoding_any_bytes_gives_a_frame_or_a_frame_error(data: bytes) -> None:
    try:
        frame = decode_ascii_frame(data)
    except FrameError as error:
        _one_sentence(str(error))
    else:
        assert decode_ascii_frame(encode_ascii_frame(frame.unit, frame.pdu)) == frame


_HEX_TEXT = re.compile(rb"(?:[0-9A-Fa-f]{2})*")


@settings(max_examples=500)
@given(
    st.lists(
        st.sampled_from(b"0123456789abcdefABCDEF") | st.sampled_from(b" \t\n\x0b\x0c\rgG:\xa0\xff"),
        min_size=6,
        max_size=40,
    ).map(bytes),
    st.booleans(),
)
def test_the_hex_check_takes_exactly_the_texts_of_hex_pairs(body: bytes, fix_lrc: bool) -> None:
    # The check decodes with bytes.fromhex, which skips whitespace: its length check must
    # refuse every text but pairs of hex digits, with the regex's words.
    if fix_lrc and _HEX_TEXT.fullmatch(body) and len(body) >= 6:
        data = bytes.fromhex(body.decode())
        body = (data[:-1] + bytes((lrc(data[:-1]),))).hex().encode()
    try:
        data = check_ascii_body(body)
    except LRCError:
        assert _HEX_TEXT.fullmatch(body)
    except FrameError as error:
        assert not _HEX_TEXT.fullmatch(body) or len(body) % 2
        _one_sentence(str(error))
    else:
        assert _HEX_TEXT.fullmatch(body)
        assert data == bytes.fromhex(body.decode())


# -- the receiver's table ---------------------------------------------------------------


def test_the_table_names_only_real_actions() -> None:
    receiver = AsciiReceiver()
    for target, action in ASCII_TRANSITIONS.values():
        assert isinstance(target, AsciiState)
        assert callable(getattr(receiver, f"_{action}"))


def test_a_pair_missing_from_the_table_raises() -> None:
    receiver = AsciiReceiver()
    assert (AsciiState.IDLE, AsciiEvent.TIMEOUT) not in ASCII_TRANSITIONS
    with pytest.raises(ReceiverError, match="TIMEOUT in state IDLE"):
        receiver._fire(AsciiEvent.TIMEOUT, b"", 0, 0.0)


def _spied(receiver: AsciiReceiver) -> list[tuple[AsciiState, AsciiEvent]]:
    """The (state, event) pairs the receiver fires from now on, in order."""
    seen: list[tuple[AsciiState, AsciiEvent]] = []
    original = receiver._fire

    def spy(event: AsciiEvent, data: bytes, position: int, now: float) -> int:
        seen.append((receiver.state, event))
        return original(event, data, position, now)

    receiver._fire = spy  # type: ignore[method-assign]
    return seen


def test_every_event_goes_through_the_table() -> None:
    # A frame fed whole is one event, FRAME; fed in two pieces, the spec's four.
    receiver = AsciiReceiver()
    seen = _spied(receiver)
    assert _frames(receiver.feed(READ, 0.0)) == [bytes.fromhex("010300000001FB")]
    assert seen == [(AsciiState.IDLE, AsciiEvent.FRAME)]
    seen.clear()
    assert receiver.feed(READ[:5], 1.0) == []
    assert _frames(receiver.feed(READ[5:], 1.01)) == [bytes.fromhex("010300000001FB")]
    assert seen == [
        (AsciiState.IDLE, AsciiEvent.START),
        (AsciiState.RECEPTION, AsciiEvent.CHARS),
        (AsciiState.RECEPTION, AsciiEvent.CHARS),
        (AsciiState.RECEPTION, AsciiEvent.CR),
        (AsciiState.WAITING_END, AsciiEvent.END),
    ]
    assert receiver.state is AsciiState.IDLE


@pytest.mark.parametrize(
    ("chunk", "events"),
    [
        # Noise, then two whole frames: noise, FRAME, FRAME.
        (b"xy" + READ + READ, ["CHARS", "FRAME", "FRAME"]),
        # A ':' inside: the first ':' is no whole frame, the second begins one.
        (b":01" + READ, ["START", "CHARS", "START", "CHARS", "CR", "END"]),
        # A CR inside, not followed by the delimiter: NO_END, then noise.
        (READ[:5] + b"\r" + READ[5:], ["START", "CHARS", "CR", "CHARS", "CHARS"]),
        # The end missing, or another character in place of the delimiter.
        (READ[:-1], ["START", "CHARS", "CR"]),
        (READ[:-1] + b"!", ["START", "CHARS", "CR", "CHARS"]),
        # 511 characters between ':' and CR: one too many for a frame.
        (b":" + b"0" * 511 + b"\r\n", ["START", "CHARS", "OVERLONG", "CHARS"]),
        # 510: the longest frame, whole (its LRC fails: reported by FRAME's check).
        (b":" + b"0" * 508 + b"01\r\n", ["FRAME"]),
    ],
)
def test_only_an_uninterrupted_frame_is_one_event(chunk: bytes, events: list[str]) -> None:
    receiver = AsciiReceiver()
    seen = _spied(receiver)
    receiver.feed(chunk, 0.0)
    assert [event.name for _, event in seen] == events


def test_a_whole_frame_with_a_bad_check_is_discarded_as_in_four_steps() -> None:
    for chunk, reason in [
        (READ[:-4] + b"FC\r\n", AsciiDiscardReason.LRC),
        (READ[:5] + b"g" + READ[6:], AsciiDiscardReason.MALFORMED),
        (b":\r\n", AsciiDiscardReason.MALFORMED),
    ]:
        (whole,) = AsciiReceiver().feed(chunk, 2.0)
        split = AsciiReceiver()
        (steps,) = split.feed(chunk[:2], 2.0 - (len(chunk) - 2) * split.char_time) + split.feed(
            chunk[2:], 2.0
        )
        assert isinstance(whole, AsciiFrameDiscarded)
        assert whole.reason is reason
        _assert_same([whole], [steps])


def _merge_noise(outputs: list[AsciiReceiverOutput]) -> list[AsciiReceiverOutput]:
    """The outputs with each run of noise discards as one (a run of noise is reported once per
    chunk it arrived in)."""
    merged: list[AsciiReceiverOutput] = []
    for out in outputs:
        last = merged[-1] if merged else None
        if (
            isinstance(out, AsciiFrameDiscarded)
            and out.reason is AsciiDiscardReason.NOISE
            and isinstance(last, AsciiFrameDiscarded)
            and last.reason is AsciiDiscardReason.NOISE
        ):
            merged[-1] = AsciiFrameDiscarded(
                last.data + out.data, out.reason, last.start, out.end, out.detail
            )
        else:
            merged.append(out)
    return merged


def _assert_same(got: list[AsciiReceiverOutput], expected: list[AsciiReceiverOutput]) -> None:
    """The same outputs, noise runs merged, times to the nanosecond (computed in other orders)."""
    got, expected = _merge_noise(got), _merge_noise(expected)
    assert [replace(out, start=0.0, end=0.0) for out in got] == [
        replace(out, start=0.0, end=0.0) for out in expected
    ]
    times = [time for out in got for time in (out.start, out.end)]
    assert times == pytest.approx([t for out in expected for t in (out.start, out.end)], abs=1e-9)


# -- framing --------------------------------------------------------------------------


def _split(stream: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({cut % (len(stream) + 1) for cut in cuts})
    edges = [0, *points, len(stream)]
    return [stream[a:b] for a, b in itertools.pairwise(edges) if b > a]


@settings(max_examples=200)
@given(
    st.lists(st.tuples(units, pdus), min_size=1, max_size=6),
    st.lists(st.integers(0, 10_000), max_size=12),
    st.lists(st.binary(max_size=20).map(lambda b: b.replace(b":", b"")), max_size=7),
    st.booleans(),
)
def test_frames_survive_any_split_and_garbage_between_them(
    frames: list[tuple[int, bytes]], cuts: list[int], garbage: list[bytes], lower: bool
) -> None:
    stream = bytearray()
    for index, (unit, pdu) in enumerate(frames):
        stream += garbage[index] if index < len(garbage) else b""
        frame = encode_ascii_frame(unit, pdu)
        stream += frame.lower() if lower else frame
    receiver = AsciiReceiver()
    outputs: list[AsciiReceiverOutput] = []
    for step, chunk in enumerate(_split(bytes(stream), cuts)):
        outputs += receiver.feed(chunk, step * 0.01)
    received = [out for out in outputs if isinstance(out, AsciiFrameReceived)]
    assert [(out.unit, out.pdu) for out in received] == frames
    assert set(_discards(outputs)) <= {AsciiDiscardReason.NOISE}
    assert receiver.state is AsciiState.IDLE


@settings(max_examples=300)
@given(st.binary(max_size=1200), st.lists(st.integers(0, 10_000), max_size=10))
def test_a_frame_whose_lrc_fails_is_never_accepted(data: bytes, cuts: list[int]) -> None:
    receiver = AsciiReceiver()
    for step, chunk in enumerate(_split(data, cuts)):
        for out in receiver.feed(chunk, step * 0.01):
            if isinstance(out, AsciiFrameReceived):
                assert sum(out.frame) & 0xFF == 0
                assert len(out.frame) >= 3
                text = out.frame.hex().encode()
                assert text in data.lower()
            else:
                _one_sentence(out.detail)


@pytest.mark.parametrize("seed", range(20))
def test_a_corrupted_character_never_passes(seed: int) -> None:
    rng = random.Random(seed)
    pdu = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
    frame = bytearray(encode_ascii_frame(rng.randrange(1, 248), pdu))
    index = rng.randrange(1, len(frame) - 2)
    original = frame[index]
    frame[index] = rng.choice([c for c in b"0123456789ABCDEF" if c != original])
    outputs = AsciiReceiver().feed(bytes(frame), 1.0)
    assert _frames(outputs) == [], f"seed {seed}: {bytes(frame)!r}"
    assert _discards(outputs) == [AsciiDiscardReason.LRC], f"seed {seed}"


def test_a_colon_inside_a_frame_starts_a_new_one() -> None:
    receiver = AsciiReceiver()
    outputs = receiver.feed(b":0103" + READ + b":01" + b"\r" + READ, 0.1)
    assert _frames(outputs) == [bytes.fromhex("010300000001FB")] * 2
    assert _discards(outputs) == [AsciiDiscardReason.RESTART] * 2
    restart = outputs[0]
    assert isinstance(restart, AsciiFrameDiscarded)
    assert restart.data == b":0103"


def test_bad_frames_are_reported_with_their_reason() -> None:
    receiver = AsciiReceiver()
    outputs = receiver.feed(b"noise:0103000\r\n:010300000001FC\r\n:010300000001FB\rX" + READ, 0.0)
    assert _discards(outputs) == [
        AsciiDiscardReason.NOISE,
        AsciiDiscardReason.MALFORMED,
        AsciiDiscardReason.LRC,
        AsciiDiscardReason.NO_END,
    ]
    assert _frames(outputs) == [bytes.fromhex("010300000001FB")]
    lost = [out for out in outputs if isinstance(out, AsciiFrameDiscarded)]
    assert b"".join(out.data for out in lost) + READ == (
        b"noise:0103000\r\n:010300000001FC\r\n:010300000001FB\rX" + READ
    )


def test_an_overlong_frame_is_dropped_and_the_next_one_taken() -> None:
    longest = encode_ascii_frame(1, bytes(253))
    receiver = AsciiReceiver()
    outputs = receiver.feed(longest, 0.0)
    assert _frames(outputs) == [b"\x01" + bytes(253) + bytes((lrc(b"\x01"),))]
    too_long = b":" + b"00" * 256 + b"\r\n"
    outputs = receiver.feed(too_long + READ, 1.0)
    assert _discards(outputs) == [AsciiDiscardReason.OVERLONG, AsciiDiscardReason.NOISE]
    first = outputs[0]
    assert isinstance(first, AsciiFrameDiscarded)
    assert len(first.data) == MAX_ASCII_FRAME_LENGTH - 1  # ':' and 511 characters: one over
    assert _frames(outputs) == [bytes.fromhex("010300000001FB")]
    assert len(receiver._buffer) == 0


@given(st.integers(1, 5000))
def test_memory_stays_bounded_without_delimiters(size: int) -> None:
    receiver = AsciiReceiver()
    receiver.feed(b":" + b"A" * size, 0.0)
    assert len(receiver._buffer) <= MAX_ASCII_FRAME_LENGTH


# -- timing ---------------------------------------------------------------------------


def test_a_gap_over_the_timeout_drops_the_frame() -> None:
    receiver = AsciiReceiver(timeout=0.5)
    receiver.feed(READ[:7], 10.0)
    assert receiver.next_deadline() == pytest.approx(10.5)
    assert receiver.expire(10.5) == []
    outputs = receiver.feed(READ[7:], 10.6)
    assert _discards(outputs) == [AsciiDiscardReason.TIMEOUT, AsciiDiscardReason.NOISE]
    assert _frames(outputs) == []
    assert receiver.next_deadline() is None


def test_a_gap_within_the_timeout_keeps_the_frame() -> None:
    receiver = AsciiReceiver()  # 1 s, the spec's default
    receiver.feed(READ[:7], 10.0)
    outputs = receiver.feed(READ[7:], 10.9)
    assert _frames(outputs) == [bytes.fromhex("010300000001FB")]


def test_expire_drops_a_stalled_frame_at_its_deadline() -> None:
    receiver = AsciiReceiver(timeout=0.25)
    receiver.feed(READ[:-1], 3.0)
    assert receiver.state is AsciiState.WAITING_END
    assert receiver.expire(3.2) == []
    outputs = receiver.expire(3.3)
    assert _discards(outputs) == [AsciiDiscardReason.TIMEOUT]
    dropped = outputs[0]
    assert isinstance(dropped, AsciiFrameDiscarded)
    assert dropped.end == pytest.approx(3.25)
    assert dropped.data == READ[:-1]
    assert receiver.state is AsciiState.IDLE


def test_times_are_the_arrivals_of_colon_and_delimiter() -> None:
    receiver = AsciiReceiver()
    char = 10 / 9600  # the default line: 9600 baud, 7E1, 10 bits a character
    (out,) = receiver.feed(READ, 5.0)
    assert isinstance(out, AsciiFrameReceived)
    assert out.end == 5.0
    assert out.start == pytest.approx(5.0 - (len(READ) - 1) * char, rel=0, abs=1e-12)


def test_bad_settings_are_refused() -> None:
    with pytest.raises(InvalidValue, match="timeout"):
        AsciiReceiver(timeout=0)
    with pytest.raises(InvalidValue, match="delimiter"):
        AsciiReceiver(delimiter=ord(":"))


# -- the delimiter of Diagnostics 08/03 -------------------------------------------------


def test_a_changed_delimiter_ends_frames_in_place_of_lf() -> None:
    receiver = AsciiReceiver()
    receiver.delimiter = ord("!")
    bang = encode_ascii_frame(1, bytes.fromhex("03 00 00 00 01"), delimiter=ord("!"))
    assert bang.endswith(b"\r!")
    outputs = receiver.feed(READ + bang, 0.0)
    assert _discards(outputs) == [AsciiDiscardReason.NO_END]
    assert _frames(outputs) == [bytes.fromhex("010300000001FB")]


def test_cr_may_be_the_delimiter() -> None:
    receiver = AsciiReceiver(delimiter=0x0D)
    outputs = receiver.feed(READ[:-1] + b"\r", 0.0)
    assert _frames(outputs) == [bytes.fromhex("010300000001FB")]


# -- a frame in one event against the four steps ------------------------------------------

DELIMITERS = (0x0A, 0x0D, ord("!"), ord("A"))


@st.composite
def _pieces(draw: st.DrawFn, delimiter: int) -> bytes:
    """A frame (good, lower case, cut short, one character changed, too long) or line noise
    rich in ':', CR and delimiters."""
    frame = encode_ascii_frame(draw(units), draw(pdus.filter(lambda p: len(p) < 40)), delimiter)
    kind = draw(st.sampled_from(["good", "lower", "short", "changed", "long", "noise"]))
    if kind == "lower":
        return frame.lower()
    if kind == "short":
        return frame[: draw(st.integers(0, len(frame) - 1))]
    if kind == "changed":
        index = draw(st.integers(0, len(frame) - 1))
        return frame[:index] + bytes((draw(st.integers(0, 255)),)) + frame[index + 1 :]
    if kind == "long":
        return b":" + b"0" * draw(st.integers(508, 513)) + bytes((0x0D, delimiter))
    alphabet = st.sampled_from(b":\r\n!A0F") | st.integers(0, 255)
    return bytes(draw(st.lists(alphabet, max_size=12)))


@st.composite
def _segments(draw: st.DrawFn, delimiter: int) -> list[tuple[bytes, float, bool]]:
    """Runs of back-to-back characters, each with the silence before it in timeouts (none,
    half, two) and whether the receiver is told the time before it arrives."""
    return draw(
        st.lists(
            st.tuples(
                st.lists(_pieces(delimiter), min_size=1, max_size=5).map(b"".join),
                st.sampled_from([0.0, 0.5, 2.0]),
                st.booleans(),
            ),
            min_size=1,
            max_size=4,
        )
    )


@settings(max_examples=400, print_blob=True)
@given(st.sampled_from(DELIMITERS), st.data())
def test_chunks_give_what_characters_one_by_one_give(delimiter: int, data: st.DataObject) -> None:
    # Fed one character at a time, a frame always takes the four steps; fed in chunks cut at
    # random points, whole frames take FRAME. Both give the same frames, the same discards
    # (and so the same counts by reason), at the same times, in the same state.
    segments = data.draw(_segments(delimiter))
    whole = AsciiReceiver(timeout=0.5, delimiter=delimiter)
    single = AsciiReceiver(timeout=0.5, delimiter=delimiter)
    char = whole.char_time
    start = 10.0
    for stream, silence, tell in segments:
        start += silence * whole.timeout
        if tell:
            _assert_same(whole.expire(start), single.expire(start))
        got: list[AsciiReceiverOutput] = []
        expected: list[AsciiReceiverOutput] = []
        cuts = data.draw(st.lists(st.integers(0, len(stream)), max_size=6))
        for chunk_start, chunk in zip(
            _chunk_starts(stream, cuts), _split(stream, cuts), strict=True
        ):
            got += whole.feed(chunk, start + (chunk_start + len(chunk) - 1) * char)
        for index in range(len(stream)):
            expected += single.feed(stream[index : index + 1], start + index * char)
        _assert_same(got, expected)
        assert whole.state is single.state
        assert whole._buffer == single._buffer
        assert whole.next_deadline() == pytest.approx(single.next_deadline(), abs=1e-9)
        start += len(stream) * char


def _chunk_starts(stream: bytes, cuts: list[int]) -> list[int]:
    """Where each of `_split(stream, cuts)`'s chunks begins in `stream`."""
    points = sorted({cut % (len(stream) + 1) for cut in cuts})
    edges = [0, *points, len(stream)]
    return [a for a, b in itertools.pairwise(edges) if b > a]


def test_the_differential_streams_take_the_whole_frame_step() -> None:
    # The differential test above is worth something only if its chunks take FRAME.
    receiver = AsciiReceiver(delimiter=ord("A"))
    seen = _spied(receiver)
    bang = encode_ascii_frame(1, b"\x03\x00\x00\x00\x01", delimiter=ord("A"))
    assert len(_frames(receiver.feed(b"\x00" + bang + bang[:4], 0.0))) == 1
    assert [event for _, event in seen].count(AsciiEvent.FRAME) == 1
