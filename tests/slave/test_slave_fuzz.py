"""Random and mutated frames at the slave: it never crashes and never answers a bad CRC."""

from __future__ import annotations

import os

import anyio
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.rtu import crc16, decode_frame, encode_frame

from .helpers import UNIT, example_store, slave_line

_VALID_REQUESTS = [
    encode_frame(UNIT, bytes.fromhex(pdu))
    for pdu in (
        "03 00 6B 00 03",
        "01 00 13 00 13",
        "06 00 01 00 03",
        "10 00 01 00 02 04 00 0A 01 02",
        "0F 00 13 00 0A 02 CD 01",
        "17 00 03 00 06 00 0E 00 03 06 00 FF 00 FF 00 FF",
        "07",
    )
]


@st.composite
def mutated_frames(draw: st.DrawFn) -> bytes:
    frame = bytearray(draw(st.sampled_from(_VALID_REQUESTS)))
    for _ in range(draw(st.integers(1, 3))):
        index = draw(st.integers(0, len(frame) - 1))
        frame[index] ^= draw(st.integers(1, 255))
    return bytes(frame)


_FRAMES = st.lists(
    st.one_of(st.binary(min_size=1, max_size=40), mutated_frames()), min_size=1, max_size=4
)


def _answerable(frame: bytes) -> bool:
    """A frame the slave may answer: a good CRC, addressed to its unit."""
    return len(frame) >= 4 and crc16(frame) == 0 and frame[0] == UNIT


# HYPOTHESIS_PROFILE=long (tests/conftest.py) makes this the long soak.
@settings(max_examples=5_000 if os.environ.get("HYPOTHESIS_PROFILE") == "long" else 40)
@given(_FRAMES)
def test_fuzzed_frames_never_crash_and_bad_crc_gets_no_reply(frames: list[bytes]) -> None:
    async def scenario() -> None:
        async with slave_line({UNIT: example_store()}) as (master, slave):
            for frame in frames:
                await master.send(frame)
                await anyio.sleep(0.008)
            # A valid read after the noise: its reply marks the end of what was answered.
            await anyio.sleep(0.01)
            await master.send_request(UNIT, "07")
            replies: list[bytes] = []
            while True:
                reply = await master.receive_frame(wait=1.0)
                assert reply is not None, "the slave stopped answering"
                decoded = decode_frame(reply)
                if decoded.pdu == bytes.fromhex("07 6D"):
                    break
                replies.append(reply)
            assert len(replies) <= sum(_answerable(frame) for frame in frames)
            assert slave.machine.state.name == "IDLE"

    anyio.run(scenario)
