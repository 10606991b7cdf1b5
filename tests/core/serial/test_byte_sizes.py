"""A line's byte size: 5 to 8 data bits, as a UART has them."""

from __future__ import annotations

import pytest

from aiortu.core.errors import InvalidValue
from aiortu.core.serial import LineSettings


@pytest.mark.parametrize("bytesize", [5, 6, 7, 8])
def test_5_to_8_data_bits_are_taken(bytesize: int) -> None:
    assert LineSettings(9600, bytesize=bytesize).bytesize == bytesize


@pytest.mark.parametrize("bytesize", [4, 9])
def test_other_byte_sizes_are_refused_in_one_sentence(bytesize: int) -> None:
    with pytest.raises(InvalidValue) as raised:
        LineSettings(9600, bytesize=bytesize)
    assert str(raised.value) == f"bytesize must be 5, 6, 7 or 8, not {bytesize}"
