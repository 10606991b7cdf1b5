"""A register read's reply with another count than the one asked gets the same error,
whichever read asked: the decoded one, the one kept as bytes, or read/write multiple."""

from __future__ import annotations

import pytest

from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu import (
    RawRegisterRead,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadWriteMultipleRegistersRequest,
    ReadWriteMultipleRegistersResponse,
    Request,
    Response,
)

_THREE_ASKED_TWO_CAME = [
    (ReadHoldingRegistersRequest(0, 3), ReadHoldingRegistersResponse((1, 2))),
    (RawRegisterRead(0x03, bytes.fromhex("0000 0003")), ReadHoldingRegistersResponse((1, 2))),
    (
        ReadWriteMultipleRegistersRequest(0, 3, 0, (1,)),
        ReadWriteMultipleRegistersResponse((1, 2)),
    ),
]


@pytest.mark.parametrize(("request_", "reply"), _THREE_ASKED_TWO_CAME)
def test_a_reply_with_fewer_registers_names_the_byte_count_asked(
    request_: Request, reply: Response
) -> None:
    with pytest.raises(MalformedPDU) as raised:
        request_.check_response(reply)
    assert (raised.value.field, raised.value.value, raised.value.allowed) == (
        "byte_count",
        4,
        range(6, 7),
    )
    assert str(raised.value) == (
        "reply register count does not match the count asked: byte_count = 4, allowed 6..6"
    )
