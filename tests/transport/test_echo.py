"""The local echo filter: exact stripping whatever the chunking, and the mismatch policy."""

from __future__ import annotations

import itertools

from hypothesis import given
from hypothesis import strategies as st

from aiortu.transport import LocalEchoFilter


def split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({0, len(data), *(cut % (len(data) + 1) for cut in cuts)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


@given(
    sent=st.lists(st.binary(min_size=1, max_size=40), min_size=1, max_size=4),
    reply=st.binary(max_size=60),
    cuts=st.lists(st.integers(0, 500), max_size=12),
)
def test_echo_is_stripped_exactly_however_it_is_split(
    sent: list[bytes], reply: bytes, cuts: list[int]
) -> None:
    echo = LocalEchoFilter()
    for chunk in sent:
        echo.expect(chunk)
    echoed = b"".join(sent)
    out = b"".join(echo.feed(piece) for piece in split(echoed + reply, cuts))
    assert out == reply
    assert echo.echoed == len(echoed)
    assert echo.mismatches == 0
    assert echo.pending == 0


@given(
    sent=st.binary(min_size=2, max_size=40),
    data=st.data(),
    cuts=st.lists(st.integers(0, 500), max_size=8),
)
def test_mismatch_passes_the_rest_on(sent: bytes, data: st.DataObject, cuts: list[int]) -> None:
    at = data.draw(st.integers(0, len(sent) - 1))
    wrong = (sent[at] ^ data.draw(st.integers(1, 255))).to_bytes(1, "big")
    received = sent[:at] + wrong + sent[at + 1 :] + b"\x11\x03"
    echo = LocalEchoFilter()
    echo.expect(sent)
    out = b"".join(echo.feed(piece) for piece in split(received, cuts))
    assert out == received[at:]
    assert (echo.echoed, echo.mismatches, echo.pending) == (at, 1, 0)


def test_nothing_expected_passes_everything() -> None:
    echo = LocalEchoFilter()
    assert echo.feed(b"\x01\x02") == b"\x01\x02"
    assert echo.feed(b"") == b""


def test_reset_forgets_the_expected_echo() -> None:
    echo = LocalEchoFilter()
    echo.expect(b"\x01\x02\x03")
    assert echo.feed(b"\x01") == b""
    echo.reset()
    assert echo.pending == 0
    assert echo.feed(b"\x02\x03") == b"\x02\x03"


def test_an_echo_that_never_comes_is_not_expected_for_ever() -> None:
    # An adapter that drops the echo, and a device that answers nothing, 500 times.
    echo = LocalEchoFilter()
    request = bytes.fromhex("11 03 00 6b 00 03 76 87")
    for _ in range(500):
        echo.expect(request)
    assert echo.pending <= 256
    assert echo.missing == 500 * len(request) - echo.pending
    # What is still expected is the latest requests' echo, whole frames of it.
    assert echo.pending % len(request) == 0
    backlog = request * (echo.pending // len(request))
    assert echo.feed(backlog + b"\x11\x03\x06") == b"\x11\x03\x06"
    assert (echo.pending, echo.mismatches) == (0, 0)
