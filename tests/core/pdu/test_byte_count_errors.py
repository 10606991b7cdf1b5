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


@pytest.mark.parametrize(
    ("pdu", "name", "right"),
    [
        ("10 0000 0002 03 000100", "WriteMultipleRegistersRequest", 4),
        ("17 0000 0001 0010 0003 05 0001000200", "ReadWriteMultipleRegistersRequest", 6),
    ],
)
def test_a_register_write_with_the_wrong_byte_count_names_the_right_one(
    pdu: str, name: str, right: int
) -> None:
    """Two bytes a register: the error names that, not the byte count that came."""
    with pytest.raises(MalformedPDU) as raised:
        decode_request(bytes.fromhex(pdu))
    assert raised.value.field == "byte_count"
    assert raised.value.allowed == range(right, right + 1)
    assert str(raised.value) == (
        f"{name}: byte count does not match the count: "
        f"byte_count = {right - 1}, allowed {right}..{right}"
    )
