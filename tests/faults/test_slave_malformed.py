"""Requests with good CRCs and malformed PDUs, for every function code, at the slave.

Every answer is a spec exception for the request's code or a reply that answers it;
nothing answers a broadcast or another unit; the slave never crashes and answers a good
request after each one. ``benchmarks/soak_faults.py`` runs the same check for minutes.
"""

from __future__ import annotations

import anyio
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.codes import FunctionCode
from aiortu.core.rtu import encode_frame

from .slave_scenarios import (
    CODES,
    KINDS,
    OTHER_UNITS,
    UNIT,
    check_answers,
    malformed_pdu,
    slave_under_test,
)

_REQUESTS = st.lists(
    st.tuples(
        st.sampled_from((UNIT, UNIT, UNIT, *OTHER_UNITS)),
        st.sampled_from(CODES),
        st.sampled_from(KINDS),
        st.binary(max_size=24),
        st.integers(0, 1 << 16),
    ),
    min_size=1,
    max_size=8,
)


@settings(max_examples=30)
@given(_REQUESTS)
def test_malformed_requests_get_a_spec_answer_or_none(
    requests: list[tuple[int, int, str, bytes, int]],
) -> None:
    async def scenario() -> None:
        async with slave_under_test() as under_test:
            for unit, code, kind, noise, position in requests:
                pdu = malformed_pdu(code, kind, noise, position)
                assert await under_test.exchange(unit, pdu) == []

    anyio.run(scenario)


async def test_every_code_and_every_spoiling_once() -> None:
    # The same walk each run: each code, each way of spoiling it, to the unit served.
    async with slave_under_test() as under_test:
        for code in (*FunctionCode, 0x41):
            for kind in KINDS:
                pdu = malformed_pdu(code, kind, b"\x5a\xa5\x01", 3)
                assert await under_test.exchange(UNIT, pdu) == []


async def test_broadcast_and_other_units_get_no_answer() -> None:
    async with slave_under_test() as under_test:
        for unit in OTHER_UNITS:
            for code in (0x03, 0x08, 0x2B, 0x41):
                pdu = malformed_pdu(code, "byte", b"\x01", 1)
                assert await under_test.exchange(unit, pdu) == []


def test_the_check_catches_what_it_must() -> None:
    # The checker itself: an answer to a broadcast, a non-spec exception, two answers.
    reply = bytes.fromhex("11 83 02 C1 34")
    assert check_answers(0, b"\x03", [reply])
    assert check_answers(UNIT, b"\x03", [bytes.fromhex("11 83 0C") + b"\x00\x00"])
    assert check_answers(UNIT, b"\x03\x00\x00\x00\x01", [reply, reply])
    assert check_answers(UNIT, b"\x03\x00\x00\x00\x01", [reply]) == []


async def test_a_request_followed_by_its_crcs_low_byte_is_that_request() -> None:
    # Found by the fault soak (seed 644211623): "01 00 13 00 13" and the low byte of its
    # CRC (8E) make a frame whose CRC ends in 00, so its first 8 bytes are the request
    # with a good CRC. The slave answers that request; the check must accept it.
    request = bytes.fromhex("01 00 13 00 13")
    assert encode_frame(UNIT, request + b"\x8e") == encode_frame(UNIT, request) + b"\x00"
    async with slave_under_test() as under_test:
        assert await under_test.exchange(UNIT, request + b"\x8e") == []
        assert await under_test.exchange(UNIT, bytes.fromhex("2b 0e 01 00 b1")) == []
