"""A byte count that does not match the count names the one it should be."""

from __future__ import annotations

import pytest

from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu import decode_request


def test_a_coil_write_with_the_wrong_byte_count_names_the_right_one() -> None:
    with pytest.raises(MalformedPDU) as raised:
        decode_request(bytes.fromhex("0F 0000 000A 01 FF"))  # 10 coils need 2 bytes
    assert raised.value.field == "byte_count"
    assert raised.value.allowed == range(2, 3)
    assert str(raised.value) == (
        "WriteMultipleCoilsRequest: byte count does not match the count: "
        "byte_count = 1, allowed 2..2"
    )
