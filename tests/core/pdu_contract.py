"""Checks every PDU class must pass, shared by the PDU test modules."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from aiortu.core.errors import InvalidValue, MalformedPDU
from aiortu.core.pdu import MAX_PDU_LENGTH, PDU, Request, decode_request, decode_response


def assert_round_trip(pdu: PDU) -> None:
    """``decode(encode())`` gives *pdu* back, by its class and by the registry."""
    encoded = pdu.encode()
    assert 1 <= len(encoded) <= MAX_PDU_LENGTH
    assert type(pdu).decode(encoded) == pdu
    registry = decode_request if isinstance(pdu, Request) else decode_response
    decoded = registry(encoded)
    assert type(decoded) is type(pdu)
    assert decoded == pdu
    assert decoded.encode() == encoded


def assert_only_malformed(decode: Callable[[bytes], object], data: bytes) -> None:
    """Decoding *data* either works, re-encoding to the same bytes, or raises MalformedPDU."""
    try:
        decoded = decode(data)
    except MalformedPDU as error:
        code: int | None = error.exception_code
    else:
        code = None
    if code is not None:
        assert code in (1, 2, 3)
        return
    assert isinstance(decoded, PDU)
    assert decoded.encode() == data


def assert_invalid(
    build: Callable[[], object],
    error_class: type[InvalidValue],
    field: str,
    value: object,
    allowed: object = None,
) -> None:
    """Building raises *error_class* (exactly) naming *field*, *value* and *allowed*."""
    with pytest.raises(error_class) as caught:
        build()
    assert type(caught.value) is error_class
    assert caught.value.field == field
    assert caught.value.value == value
    if allowed is not None:
        assert caught.value.allowed == allowed
    assert field in str(caught.value)
