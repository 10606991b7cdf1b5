"""A Report Server ID (11) answer fits its reply: id, run indicator and data, 250 bytes."""

from __future__ import annotations

import pytest

from aiortu.core.errors import InvalidValue
from aiortu.core.model import ServerId
from aiortu.core.pdu import ReportServerIdResponse, decode_response


@pytest.mark.parametrize("data_length", [0, 1, 248])
def test_an_answer_of_exactly_250_bytes_is_taken_and_encodes(data_length: int) -> None:
    """The run indicator takes one byte: an id and data of 249 bytes together just fit."""
    answer = ServerId(b"\x11" * (249 - data_length), False, b"d" * data_length)
    response = ReportServerIdResponse(
        answer.server_id, answer.run_indicator, answer.additional_data
    )
    pdu = response.encode()
    assert pdu[1] == 250  # the byte count
    assert decode_response(pdu) == response


@pytest.mark.parametrize("data_length", [0, 1, 249])
def test_one_byte_more_is_refused_with_the_total(data_length: int) -> None:
    with pytest.raises(InvalidValue) as raised:
        ServerId(b"\x11" * (250 - data_length), True, b"d" * data_length)
    assert raised.value.field == "len(server_id) + 1 + len(additional_data)"
    assert raised.value.value == 251
    assert raised.value.allowed == range(2, 251)


def test_an_empty_id_is_refused() -> None:
    with pytest.raises(InvalidValue, match="server_id"):
        ServerId(b"", True, b"data")
